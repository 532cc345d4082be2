"""Joint training of 3D-GS and per-Gaussian object features: the options and schedules
(:mod:`~gsseg.train.config`), the trainer, its losses, optimiser, densification strategy and
views. The package loads nothing itself: the command lines read the options without the
trainer."""
