"""What every command of the project relies on, whatever its stage: the one error type and
failures (``errors``), writes that appear whole (``atomic``), folder locks (``locks``),
outputs that never overwrite inputs (``overlap``), plain output names (``names``),
self-checking cache files (``checked_files``), interruptions with a checkpoint
(``interrupts``), thread counts (``threads``), local or Ray execution (``engine``) and the
command-line entry points (``cli_support``)."""
