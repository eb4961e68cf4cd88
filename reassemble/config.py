"""Configuration of a run: the options of every stage, in one place."""

from __future__ import annotations

import dataclasses


@dataclasses.dataclass(frozen=True)
class MatchConfig:
    """Options of the matching stages; lengths are fractions of the reference size (the
    median fragment bounding-box diagonal), resolved from the data.

    Parameters
    ----------
    radii : descriptor radii
    keypoint_spacing : spacing of fracture keypoints
    samples : fracture and surface samples per fragment (ICP, contact, penetration)
    max_memory : bytes of working memory one fragment's descriptor grid may take; a
        fragment that needs more is left out with a note naming ``--max-memory``
    gap : how far apart mating fracture surfaces are (material lost at the break); None:
        measured from the pairs (:func:`match_set`)
    denoise : when the set's vertex noise exceeds this fraction of the finest radius, every
        fragment is matched on a Taubin-smoothed copy (all smoothed alike, until the noisiest
        is down to half that); their own vertices stay in every output
    thin_walls : match as thin-walled sherds along their break strips (:mod:`shells`): None
        when most fragments are (:func:`shells.is_thin_shell`), or always / never
    fill_holes : close the holes of open scans up to this extent, a fraction of each mesh's
        diagonal (:func:`holes.fill_holes`); None refuses an open mesh
    signature_radii : the fracture signatures use this many of the finest ``radii`` (None:
        all of them); two by default: the coarsest ball reaches past a small contact into
        the air and other fragments, and with it the signatures of small mating faces
        disagree (``benchmarks/pairwise.py --signature-radii``)
    """

    radii: tuple[float, ...] = (0.02, 0.04, 0.08)
    keypoint_spacing: float = 0.015
    samples: int = 4000
    max_memory: float = 4e9
    gap: float | None = None
    denoise: float = 0.2
    thin_walls: bool | None = None
    fill_holes: float | None = None
    signature_radii: int | None = 2


