"""Mask proposers: one image in, candidate object masks with scores out.

- ``base``: what a proposer returns (:class:`~hqmask.proposers.base.Proposals`) and the
  interface every proposer implements (:class:`~hqmask.proposers.base.Proposer`).
- ``graph``: the weight-free default (graph segmentation, colour merging, background, and
  the cuts and joins that a view's depth allows).
- ``existing``: masks already on disk, one proposal per ID.
- ``sam-hq``: SAM-HQ's automatic mask generator through ONNX Runtime
  (:mod:`hqmask.sam_hq.proposer`).
- ``registry``: :func:`~hqmask.proposers.registry.make_proposer`, each of them by name.
"""
