"""Segmentation: prior-guided label reassignment from the contribution matrix
(:mod:`~gsseg.segment.reassign`, its options in :mod:`~gsseg.segment.label_options`), the
3D regularisations, prompts (a point, clicks) and what served a selection. The package
loads nothing itself: the command lines read the options without loading the code."""
