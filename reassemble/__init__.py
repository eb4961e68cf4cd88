"""reassemble: put broken 3D objects back together.

The data flows one way, one module per stage: describe (:mod:`descriptors`) -> segment
(:mod:`segmentation`) -> features (:mod:`features`) -> match pairs (:mod:`registration`) ->
assemble (:mod:`assembly`), run in order by :mod:`pipeline` with the options of
:mod:`config`. Files are read by :mod:`files` and :mod:`inputs` and written by :mod:`outputs`;
:mod:`synth` and :mod:`puzzle` make synthetic puzzles with ground truth, :mod:`metrics` scores.
Method notes per stage: ``docs/method/``.
"""

__version__ = "0.1.0"

from .errors import ReassembleError  # noqa: F401
