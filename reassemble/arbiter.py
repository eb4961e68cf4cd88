"""Choosing between assemblies of the same fragments without trusting any segmentation.

Two runs that segmented the fragments differently score their own placements on their own
fracture samples, so their scores cannot be compared. What can: how much of the
fragments' *whole* surfaces touch, with opposed normals, where the assembly puts them,
less what interpenetrates. A true assembly closes every break it places (contact about
the total break area between its fragments, nothing inside anything); a wrong placement
touches along a small patch or cuts into its neighbour. See ``docs/method/assembly.md``.
"""

from __future__ import annotations

import numpy as np

from .assembly import Assembly
from .features import FractureSurface
from .geometry import face_areas, face_normals, invert_transform, make_scene, sample_surface
from .registration import RegistrationParams, contact_score


def whole_surface(vertices: np.ndarray, faces: np.ndarray, count: int, *, rng: np.random.Generator) -> FractureSurface:
    """A fragment's whole surface as if it were all fracture: ``count`` area-uniform samples
    with their face normals, for :func:`registration.contact_score`."""
    vertices = np.asarray(vertices, np.float64)
    points, face = sample_surface(vertices, faces, count, rng=rng)
    normals = face_normals(vertices, faces)[face]
    area = float(face_areas(vertices, faces).sum())
    empty = np.zeros((0, 3))
    return FractureSurface(empty, empty, np.zeros((0, 0)), points, normals, area / count, points, area / count,
                           area, area)


def assembly_contact(
    assemblies: list[Assembly], meshes: list[tuple[np.ndarray, np.ndarray]], *, size: float,
    params: list[RegistrationParams], count: int = 4000, seed: int = 0,
) -> list[tuple[float, float]]:
    """Per assembly, (contact area, penetration area), mesh units squared, summed over every
    two fragments of a sub-assembly, on whole-surface samples (:func:`whole_surface`),
    drawn once per fragment for all the assemblies.

    Parameters
    ----------
    assemblies : Assemblies of the same fragments (poses in each sub-assembly's frame)
    meshes : (vertices (n, 3), faces (f, 3)) per fragment, closed, in its own coordinates
    size : reference size (mesh units); ``params.tolerance`` and ``params.gap`` are fractions of it
    params : per assembly, the RegistrationParams it was made with
    count : samples per fragment
    seed : for the samples

    Notes
    -----
    Each assembly is scored at its own ``gap``: one run may have found its mating
    surfaces a gap apart (material lost) and placed fragments that far apart, another
    none. Scored at the other's gap, a closed break counts as no contact at all (a
    4-piece noisy torus put together right scored 0.004 at the gap of a run that had
    placed only half of it, against 0.171 at its own).
    """
    if len(params) != len(assemblies):
        raise ValueError(f"{len(assemblies)} assemblies but {len(params)} RegistrationParams")
    rngs = np.random.default_rng(seed).spawn(len(meshes))
    surfaces, scenes = {}, {}

    def fragment(k):
        if k not in surfaces:
            surfaces[k] = whole_surface(*meshes[k], count, rng=rngs[k])
            scenes[k] = make_scene(*meshes[k])
        return surfaces[k], scenes[k]

    out = []
    for assembly, reg in zip(assemblies, params):
        contact = penetration = 0.0
        for g in np.unique(assembly.group):
            members = np.flatnonzero(assembly.group == g)
            for x, p in enumerate(members):
                for q in members[x + 1:]:
                    (sp, scene_p), (sq, scene_q) = fragment(p), fragment(q)
                    T_q_p = invert_transform(assembly.T_group_fragment[q]) @ assembly.T_group_fragment[p]
                    _, c, pen = contact_score(sp, sq, T_q_p, source_scene=scene_p, target_scene=scene_q,
                                              tol=reg.tolerance * size, params=reg, gap=reg.gap * size)
                    contact += c
                    penetration += pen
        out.append((contact, penetration))
    return out


def better(a: tuple[float, float], b: tuple[float, float], *, penetration_weight: float) -> bool:
    """Whether (contact, penetration) ``b`` beats ``a``: more contact less weighted
    penetration (ties keep ``a``)."""
    return b[0] - penetration_weight * b[1] > a[0] - penetration_weight * a[1]


__all__ = ["assembly_contact", "better", "whole_surface"]
