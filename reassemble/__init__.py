"""reassemble: put broken 3D objects back together.

One module per stage: meshes (:mod:`files`) -> integral invariants (:mod:`descriptors`) ->
fracture surfaces (:mod:`segmentation`) -> keypoints and signatures (:mod:`features`) ->
pairwise registration (:mod:`registration`) -> assembly (:mod:`assembly`), orchestrated by
:mod:`pipeline`; :mod:`synth` makes puzzles with ground truth and :mod:`metrics` scores a
result. Method notes per stage: ``docs/method/``.
"""

__version__ = "0.1.0"

from .errors import ReassembleError  # noqa: F401
