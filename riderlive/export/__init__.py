"""Takes as files engines import: BVH (one per skeleton) and binary glTF 2.0 with animation.

``riderlive export TAKE --format bvh|gltf`` (:mod:`riderlive.export.cli`). A take is read
and posed once (:mod:`riderlive.export.take`); :mod:`~riderlive.export.bvh` and
:mod:`~riderlive.export.gltf` only write. Axes and units: ``docs/export.md``.
"""

from riderlive.export.take import ExportError, SkeletonTrack, TakePoses, load_take, resolve_take

__all__ = ["ExportError", "SkeletonTrack", "TakePoses", "load_take", "resolve_take"]
