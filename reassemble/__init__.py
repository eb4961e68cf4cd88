"""reassemble: put broken 3D objects back together.

The data flows one way, one module per stage:
mesh (:mod:`io`) -> fracture generator for ground truth (:mod:`synth`) ->
scoring (:mod:`metrics`), with :mod:`pipeline` the only module that touches files.
"""

__version__ = "0.1.0"

from .errors import ReassembleError  # noqa: F401
