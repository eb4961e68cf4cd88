"""Segmentation of fragments into fracture surface and original (intact) surface.

Fracture surfaces are rough across scales and meet the original surface along sharp
edges; the original surface is smooth at small scales (or piecewise flat, for CAD parts).
The cues (why each, and what it was measured against: ``docs/method/segmentation.md``):

- **patches**: faces grouped by mesh connectivity without crossing a sharp edge, capped
  in size by a coarse cell grid. Sharp edges separate the two classes almost perfectly,
  so patches, not faces, are classified;
- **roughness of a patch**: the RMS residual of a quadric fitted to its surface, over the
  patch's size. Smooth and CAD surfaces fit;
- **integral-invariant roughness**: the angle between a face's normal and the normal of
  ball ∩ solid at the smallest radius, and ``(κ1 − κ2)² r²`` from its covariance.

Which patches are fracture is decided by one of two kinds of evidence (``segment.method``):

- **learned** (default): a classifier trained offline on generated puzzles of every break
  style (:mod:`segmenter`) scores each patch from its integral invariants at every radius,
  fit residuals, rim, convex-hull share and smooth-sheet size, each also relative to its
  fragment and the set, and the mixture below. "Rougher than the rest" alone inverts on
  smooth and planar breaks and on detailed originals;
- **mixture**: the roughness scores alone, as follows.

The two roughness scores are standardized over all fragments of a set, averaged, and
split by a Gaussian mixture (two or three components by BIC; the roughest is fracture,
and a middle one overlapping it; exact quadric patches, e.g. CAD faces, are original and
left out of the fit): the threshold comes from the data, not from the object. Either way a graph
cut on the patch graph (boundary length, weighted by how smooth the boundary is) then
removes isolated patches: adjacent patches on one smooth sheet take one label, a sharp
edge costs little to cut. Patches too small for a quadric fit (under noise a break
shatters into such shards) join the neighbour across their flattest boundary; those left
carry no evidence and take their neighbours' label.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .geometry import connected_components, face_adjacency, face_areas, face_normals, sample_surface, taubin_smooth


EXACT_QUADRIC = 1e-6  # relative RMS residual below which a patch is a quadric up to rounding
MERGE_SDS = 1.5  # a middle mixture component this many sds from the roughest is fracture too
METHODS = ("learned", "mixture")


@dataclass(frozen=True)
class SegmentParams:
    """Options of :func:`segment`; lengths are fractions of the reference size.

    Parameters
    ----------
    crease_angle : dihedral angle (degrees) above which an edge bounds a patch
    patch_size : edge of the cell grid that caps patch size (fraction of the reference size)
    smoothness : weight of the graph cut's boundary term against the patch evidence
    smooth_angle : dihedral angle (degrees) at which cutting a boundary costs e^-1 of a flat one.
        Low enough that the edges of noisy smooth surface (10-20 degrees) are not free to
        cut, high enough that a break met at a shallow angle can still be cut out
    samples : surface samples per fragment for the quadric fits
    min_samples : patches with fewer samples (expected) are too small for a quadric fit:
        they join a neighbour (``merge_angle``), or carry no evidence
    min_fracture_share : a mixture component labelled fracture that covers less of the
        set's area than this is joined by the next roughest
    noise_smoothing : Taubin smoothing iterations of the retry on smoothed geometry when
        the labelled fracture still covers less than ``min_fracture_share`` of the set
    merge_angle : a patch too small for a quadric fit joins the neighbour across its
        flattest boundary when that boundary's mean dihedral angle is under this (degrees;
        0: never), so a real crease stays a boundary
    method : the patch evidence the graph cut takes: ``"learned"``, the classifier shipped
        in ``reassemble/data/segmenter.npz`` (:mod:`segmenter`), or ``"mixture"``, the
        Gaussian mixture of the roughness scores, which holds only where the break is
        rougher than the object (``docs/method/segmentation.md``)
    fallback : the method a run segments with again when its assembly leaves fragments
        unplaced; the assembly with more whole-surface contact is kept
        (:mod:`arbiter`). None: never
    mates : also label fracture the planes of the surface labelled original that are the
        best mates of labelled planar break faces (:mod:`mates`): True always, False never,
        None (default) only when a run's assembly leaves fragments unplaced, before
        ``fallback`` (a prismatic part's end face matches its cross-section as well as the
        true mate does); a set registering candidate pairs only (``retrieval``) starts
        with them and tries without
    mate_overlap : the share of either outline on the other, laid together, that makes a
        plane a mate (a clean break's two faces coincide)
    whole : fragments (by name) matched by their whole surface, every face a possible
        break, whatever the evidence says (:func:`all_fracture`); None: none
    whole_retry : when a run's assembly leaves fragments unplaced after every segmentation,
        match each of them by its whole surface (``whole``), one at a time, largest first,
        and keep the assembly with more whole-surface contact (:mod:`arbiter`): a fragment
        whose break the evidence missed has no keypoint on it and finds no pair, while its
        mates' sides of the break may well have been found

    Notes
    -----
    The defaults and what each was chosen against: ``docs/method/segmentation.md``.
    """

    crease_angle: float = 30.0
    patch_size: float = 0.1
    smoothness: float = 1.0
    smooth_angle: float = 15.0
    samples: int = 30000
    min_samples: int = 12
    min_fracture_share: float = 0.1
    noise_smoothing: int = 5
    merge_angle: float = 45.0
    method: str = "learned"
    fallback: str | None = "mixture"
    mates: bool | None = None
    mate_overlap: float = 0.9
    whole: tuple[str, ...] | None = None
    whole_retry: bool = True

    def __post_init__(self):
        from .errors import ReassembleError

        for name, value in (("method", self.method), ("fallback", self.method if self.fallback is None else self.fallback)):
            if value not in METHODS:
                raise ReassembleError(f"segment.{name} must be one of {', '.join(METHODS)} (got {value!r})")


@dataclass
class Segmentation:
    """Fracture labels of one fragment.

    Attributes
    ----------
    fracture : (f,) bool, True on fracture faces
    probability : (f,) float, the evidence's probability of fracture for the face's patch (segment.method)
    patch : (f,) int, patch index per face
    region : (f,) int, fracture region per face (connected fracture faces), -1 on original
    fracture_area, area : float, fracture and total surface area
    original : (f,) bool, the faces the evidence found original, where the labels say
        otherwise (:func:`all_fracture`); None: ``~fracture``
    """

    fracture: np.ndarray
    probability: np.ndarray
    patch: np.ndarray
    region: np.ndarray
    fracture_area: float
    area: float
    original: np.ndarray | None = None


def all_fracture(seg: Segmentation) -> Segmentation:
    """``seg`` with every face labelled fracture, as one region (``SegmentParams.whole``);
    what the evidence found original is kept as ``original``, for the seams."""
    n = len(seg.fracture)
    original = ~np.asarray(seg.fracture, bool) if seg.original is None else seg.original
    return Segmentation(np.ones(n, bool), seg.probability, seg.patch, np.zeros(n, int), seg.area, seg.area,
                        original)


def labels_from_contact(seg: Segmentation, touching: np.ndarray, *, keep_open: bool) -> np.ndarray:
    """A placed fragment's fracture labels after the assembly: the faces in contact.

    Parameters
    ----------
    seg : the fragment's Segmentation (its labels and regions)
    touching : (f,) bool, faces touching another fragment of its sub-assembly
        (:func:`assembly.contact_faces`)
    keep_open : also keep the labelled fracture regions that touch nothing (a set with
        fragments outside this one's sub-assembly: their mates may be there)

    Returns
    -------
    (f,) bool

    Notes
    -----
    A break is where a fragment met its mate, so in an assembly it is the surface in
    contact, whatever either segmentation said: the complementarity of Huang et al. (2006),
    applied once the poses are known. Face by face: the segmentation's patches can straddle
    a break's rim where it meets the surface at a shallow angle. Where the assembly is
    complete, a labelled region touching nothing has no mate and is original surface.
    """
    out = np.asarray(touching, bool).copy()
    if keep_open:
        region = seg.region
        touched = np.unique(region[out & (region >= 0)])
        out |= np.asarray(seg.fracture, bool) & (region >= 0) & ~np.isin(region, touched)
    return out


def fracture_regions(fracture: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """(f,) region per face: connected fracture faces (``pairs``: face adjacency) share a
    number 0, 1, ...; -1 on original surface."""
    region = np.full(len(fracture), -1)
    idx = np.flatnonzero(fracture)
    if len(idx):
        both = fracture[pairs[:, 0]] & fracture[pairs[:, 1]]
        _, comp = connected_components(len(fracture), pairs[both])
        region[idx] = np.unique(comp[idx], return_inverse=True)[1]
    return region


def make_patches(
    vertices: np.ndarray, faces: np.ndarray, *, size: float, params: SegmentParams = SegmentParams()
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Crease-bounded, size-capped patches.

    Returns
    -------
    patch : (f,) int patch per face
    pairs : (e, 2) adjacent faces
    dihedral : (e,) degrees between the faces' normals
    """
    normals = face_normals(vertices, faces)
    pairs, _ = face_adjacency(faces)
    cos = np.einsum("ij,ij->i", normals[pairs[:, 0]], normals[pairs[:, 1]])
    dihedral = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    centres = vertices[faces].mean(axis=1)
    cell = np.floor((centres - centres.min(axis=0)) / (params.patch_size * size)).astype(np.int64)
    cell_id = np.unique(cell, axis=0, return_inverse=True)[1].ravel()
    keep = (dihedral < params.crease_angle) & (cell_id[pairs[:, 0]] == cell_id[pairs[:, 1]])
    _, patch = connected_components(len(faces), pairs[keep])
    if params.merge_angle > 0:
        area = face_areas(vertices, faces)
        patch = merge_small_patches(patch, pairs, dihedral, area, min_area=params.min_samples / params.samples
                                    * float(area.sum()), max_angle=params.merge_angle)
    return patch, pairs, dihedral


def merge_small_patches(
    patch: np.ndarray, pairs: np.ndarray, dihedral: np.ndarray, area: np.ndarray, *, min_area: float,
    max_angle: float, rounds: int = 8,
) -> np.ndarray:
    """Patches under ``min_area`` joined to the neighbour across their flattest boundary.

    Under scan noise most edges of a rough break are creases, and its patches shatter into
    shards too small for a quadric fit (on the noisy bench sets ~10 % of the fracture area,
    which then carried no evidence and was lost). A shard joins the neighbouring patch
    whose shared edges have the smallest mean dihedral angle, if that is under
    ``max_angle`` degrees (a real crease, as between a break and the original surface,
    stays a boundary); merged shards may merge again, up to ``rounds`` times.

    Parameters
    ----------
    patch : (f,) patch per face
    pairs : (e, 2) adjacent faces; dihedral : (e,) degrees
    area : (f,) face areas

    Returns
    -------
    (f,) patch per face, numbered 0, 1, ...
    """
    for _ in range(rounds):
        n = int(patch.max()) + 1
        small = np.bincount(patch, area, n) < min_area
        pu, pv = patch[pairs[:, 0]], patch[pairs[:, 1]]
        cross = pu != pv
        a, b = np.r_[pu[cross], pv[cross]], np.r_[pv[cross], pu[cross]]
        d = np.r_[dihedral[cross], dihedral[cross]]
        from_small = small[a]
        if not from_small.any():
            break
        a, b, d = a[from_small], b[from_small], d[from_small]
        key, inverse = np.unique(a.astype(np.int64) * n + b, return_inverse=True)
        mean = np.bincount(inverse, d) / np.bincount(inverse)
        ka, kb = key // n, key % n
        order = np.lexsort((mean, ka))
        first = order[np.r_[True, ka[order][1:] != ka[order][:-1]]]  # the flattest neighbour of each small patch
        first = first[mean[first] < max_angle]
        if len(first) == 0:
            break
        patch = connected_components(n, np.column_stack([ka[first], kb[first]]))[1][patch]
    return np.unique(patch, return_inverse=True)[1].ravel()


def quadric_residual(points: np.ndarray, patch_of_point: np.ndarray, n_patches: int, *, min_samples: int):
    """(n_patches,) RMS residual of a least-squares quadric height field per patch, NaN if too few points."""
    return fit_residuals(points, patch_of_point, n_patches, min_samples=min_samples)[0]


def fit_residuals(points: np.ndarray, patch_of_point: np.ndarray, n_patches: int, *, min_samples: int):
    """(n_patches,) RMS residuals of a least-squares quadric height field and of a plane per
    patch, NaN where too few points."""
    order = np.argsort(patch_of_point, kind="stable")
    bounds = np.searchsorted(patch_of_point[order], np.arange(n_patches + 1))
    out = np.full(n_patches, np.nan)
    plane = np.full(n_patches, np.nan)
    for k in np.flatnonzero(np.diff(bounds) >= min_samples):
        x = points[order[bounds[k]:bounds[k + 1]]]
        x = x - x.mean(axis=0)
        _, sv, vt = np.linalg.svd(x, full_matrices=False)
        local = x @ vt.T  # last axis: the patch's normal
        u, v, w = local.T
        A = np.column_stack([u * u, u * v, v * v, u, v, np.ones_like(u)])
        coef, *_ = np.linalg.lstsq(A, w, rcond=None)
        out[k] = np.sqrt(np.mean((w - A @ coef) ** 2))
        plane[k] = sv[-1] / np.sqrt(len(x))
    return out, plane


@dataclass
class _Fragment:
    patch: np.ndarray
    pairs: np.ndarray
    dihedral: np.ndarray
    edge_length: np.ndarray
    face_area: np.ndarray
    patch_area: np.ndarray
    log_residual: np.ndarray  # (patches,) NaN where too few samples
    face_features: np.ndarray  # (f, 2) log normal deviation, log (κ1 − κ2)² r²
    features: np.ndarray | None = None  # (patches, k) the learned method's own (segmenter.fragment_features)


def _weighted_standardize(x: np.ndarray, w: np.ndarray) -> tuple[float, float]:
    ok = np.isfinite(x)
    mean = np.average(x[ok], weights=w[ok])
    std = np.sqrt(np.average((x[ok] - mean) ** 2, weights=w[ok]))
    return float(mean), float(max(std, 1e-12))


def segment(
    meshes: list[tuple[np.ndarray, np.ndarray]],
    descriptors: list,
    *,
    size: float,
    params: SegmentParams = SegmentParams(),
    seed: int = 0,
) -> list[Segmentation]:
    """Label fracture faces on every fragment of a set.

    Parameters
    ----------
    meshes : list of (vertices (n, 3), faces (f, 3)), closed fragments
    descriptors : list of Descriptors computed at the face centres (``points`` = the mean of
        each face's vertices) with ``principal=True``; the first radius is the finest
    size : reference size (e.g. the median fragment diagonal) for patch sizes
    params : SegmentParams
    seed : seeds the surface sampling and the mixture fit

    Returns
    -------
    list of Segmentation, one per mesh
    """
    out = _segment(meshes, descriptors, size=size, params=params, seed=seed, smoothing=0)
    if _share(out) < params.min_fracture_share and params.noise_smoothing:
        # Under scan noise the crease angles and face normals are noise: patches shatter and
        # the roughness of the break drowns. Their geometry is then taken from a Taubin-smoothed
        # copy; the integral invariants, being integrals, stay. Only as a retry: where the first
        # pass finds a break, smoothing costs more than it gives (docs/method/segmentation.md).
        retry = _segment(meshes, descriptors, size=size, params=params, seed=seed, smoothing=params.noise_smoothing)
        if _share(retry) > _share(out):
            out = retry
    return out


def _share(segmentations: list[Segmentation]) -> float:
    return sum(s.fracture_area for s in segmentations) / max(sum(s.area for s in segmentations), 1e-300)


def _segment(meshes, descriptors, *, size: float, params: SegmentParams, seed: int, smoothing: int) -> list[Segmentation]:
    """One segmentation pass; with ``smoothing`` > 0 patches, face normals and quadric fits
    come from Taubin-smoothed vertices (areas from the given ones)."""
    frags, mixture, rows = patch_evidence(meshes, descriptors, size=size, params=params, seed=seed,
                                          smoothing=smoothing, learned=params.method == "learned")
    if rows is not None:
        from . import segmenter

        model = segmenter.shipped()
        probs = [model.probability(x) for x in rows]
    else:
        probs = mixture
    out = []
    for f, prob in zip(frags, probs):
        label = _tidy(f, prob, params)
        fracture = label[f.patch]
        out.append(Segmentation(
            fracture=fracture, probability=prob[f.patch], patch=f.patch, region=fracture_regions(fracture, f.pairs),
            fracture_area=float(f.face_area[fracture].sum()), area=float(f.face_area.sum()),
        ))
    return out


def patch_evidence(meshes, descriptors, *, size: float, params: SegmentParams, seed: int, smoothing: int = 0,
                   learned: bool = False):
    """The patches of every fragment and the evidence on them.

    Returns
    -------
    frags : list of _Fragment
    mixture : list of (patches,) the mixture's probability of fracture per patch
    rows : with ``learned``, list of (patches, k) features (:data:`segmenter.FEATURE_NAMES`), else None
    """
    from . import segmenter

    rng = np.random.default_rng(seed)
    frags = [_fragment_patches(given, faces, d, size=size, params=params, smoothing=smoothing, learned=learned,
                               rng=rng) for (given, faces), d in zip(meshes, descriptors)]
    mixture, scores = _mixture(frags, params=params, rng=rng)
    if not learned:
        return frags, mixture, None
    neighbours = []
    for f in frags:
        pu, pv = f.patch[f.pairs[:, 0]], f.patch[f.pairs[:, 1]]
        cross = pu != pv
        neighbours.append((np.r_[pu[cross], pv[cross]], np.r_[pv[cross], pu[cross]],
                           np.r_[f.edge_length[cross], f.edge_length[cross]]))
    rows = segmenter.set_features([f.features for f in frags], [f.patch_area for f in frags], neighbours,
                                  mixture, scores)
    return frags, mixture, rows


def _fragment_patches(given, faces, d, *, size: float, params: SegmentParams, smoothing: int, learned: bool,
                      rng: np.random.Generator) -> _Fragment:
    """One fragment's patches, quadric fits and face roughness (and the learned method's
    features); with ``smoothing``, geometry from a Taubin-smoothed copy, areas from ``given``."""
    from . import segmenter

    given, faces = np.asarray(given, float), np.asarray(faces, np.int64)
    vertices = taubin_smooth(given, faces, smoothing) if smoothing else given
    patch, pairs, dihedral = make_patches(vertices, faces, size=size, params=params)
    n_patches = int(patch.max()) + 1
    area = face_areas(given, faces)
    patch_area = np.bincount(patch, area, n_patches)
    samples, face_of_sample = sample_surface(vertices, faces, params.samples, rng=rng)
    residual, plane = fit_residuals(samples, patch[face_of_sample], n_patches, min_samples=params.min_samples)
    relative = residual / np.sqrt(np.maximum(patch_area, 1e-300))
    # an exact quadric (a CAD face, a cylinder): original surface, and no evidence for
    # the mixture, whose two components would otherwise split flat from curved
    log_residual = np.where(relative < EXACT_QUADRIC, -np.inf, np.log(relative + 1e-4))
    normal_angle = np.degrees(np.arccos(np.clip(np.abs(
        np.einsum("ij,ij->i", d.normal[:, 0], face_normals(vertices, faces))), 0.0, 1.0)))
    k2 = np.maximum(d.K2_cov[:, 0], 0.0) * d.radii[0] ** 2
    face_features = np.column_stack([np.log(normal_angle + 1e-2), np.log(k2 + 1e-5)])
    edge_vertices = face_adjacency(faces)[1]
    edge_length = np.linalg.norm(vertices[edge_vertices[:, 0]] - vertices[edge_vertices[:, 1]], axis=1)
    features = None
    if learned:
        relative_plane = plane / np.sqrt(np.maximum(patch_area, 1e-300))
        features = segmenter.fragment_features(
            vertices, faces, d, patch=patch, pairs=pairs, dihedral=dihedral, edge_length=edge_length,
            face_area=area, patch_area=patch_area, crease_angle=params.crease_angle,
            log_quadric=log_residual,
            log_plane=np.where(relative_plane < EXACT_QUADRIC, -np.inf, np.log(relative_plane + 1e-4)))
    return _Fragment(patch, pairs, dihedral, edge_length, area, patch_area, log_residual, face_features, features)


def _mixture(frags: list[_Fragment], *, params: SegmentParams, rng: np.random.Generator):
    """The mixture's evidence: per fragment (patches,) probability of fracture, and
    (patches,) roughness score (standardized over the set)."""
    from sklearn.mixture import GaussianMixture

    weights = np.concatenate([f.patch_area for f in frags])
    features = np.concatenate([f.face_features for f in frags])
    face_weights = np.concatenate([f.face_area for f in frags])
    stats = [_weighted_standardize(features[:, j], face_weights) for j in range(features.shape[1])]
    desc = []
    for f in frags:
        z_face = np.mean([(f.face_features[:, j] - m) / s for j, (m, s) in enumerate(stats)], axis=0)
        desc.append(np.bincount(f.patch, f.face_area * z_face, len(f.patch_area)) / np.maximum(f.patch_area, 1e-300))
    m_desc, s_desc = _weighted_standardize(np.concatenate(desc), weights)
    m_res, s_res = _weighted_standardize(np.concatenate([f.log_residual for f in frags]), weights)
    scores, exact = [], []
    for f, z in zip(frags, desc):
        z_desc = (z - m_desc) / s_desc
        z_res = (f.log_residual - m_res) / s_res
        scores.append(np.where(np.isnan(z_res), z_desc, 0.5 * (z_res + z_desc)))
        exact.append(np.isneginf(f.log_residual))
    pooled = np.concatenate(scores)
    informative = ~np.concatenate(exact)
    if not informative.any():
        informative[:] = True
        pooled = np.where(np.isfinite(pooled), pooled, -1e3)
    # area-weighted fit: resample patches in proportion to their area
    w = np.where(informative, weights, 0.0)
    pick = rng.choice(len(pooled), size=min(5000, 4 * int(informative.sum())), p=w / w.sum())
    state = int(rng.integers(2**31))
    fits = [GaussianMixture(k, random_state=state).fit(pooled[pick, None]) for k in (2, 3)]
    # two or three components by BIC: where the original surface is itself two kinds (thin
    # curved parts and broad faces: wingnut, CAD), two components split those, not fracture
    # from original
    fits.sort(key=lambda g: g.bic(pooled[pick, None]))
    fracture_components = functools.partial(_fracture_components, scores=pooled[informative],
                                            weights=weights[informative], min_share=params.min_fracture_share)
    # the fit with the better BIC, unless only the other one gives a break of some size
    gmm, (rough, share) = fits[0], fracture_components(fits[0])
    if share < params.min_fracture_share:
        other = fracture_components(fits[1])
        if other[1] >= params.min_fracture_share:
            gmm, (rough, share) = fits[1], other
    mixture = []
    for f, score, ex in zip(frags, scores, exact):
        prob = np.zeros(len(score))
        prob[~ex] = gmm.predict_proba(score[~ex, None])[:, rough].sum(axis=1)
        # too small for a quadric fit: no evidence, the graph cut labels it as its neighbours.
        # Its face scores alone mislead: small patches lie along creases, where the normal
        # deviation is large on either side (noisy sets: 1-12 % of the area labelled wrongly)
        small = np.isnan(f.log_residual)
        if not small.all():
            prob[small] = 0.5
        mixture.append(prob)
    return mixture, scores


def _tidy(f: _Fragment, prob: np.ndarray, params: SegmentParams) -> np.ndarray:
    """(patches,) bool fracture labels: the graph cut of the evidence ``prob``, its
    boundary weight halved until the cut tidies the evidence instead of overruling it.

    Notes
    -----
    Where the cut moves more than half the fracture area of the mixture (a fracture met at a
    shallow angle all round), its weight is halved. The same holds for each face of the
    break: a connected region of evidence the size of the fragment's other break faces is
    not noise to tidy away, and the cut may not erase it (a break met at a shallow angle
    all round its rim costs less to cut out than its area says; on that knife edge the
    outcome flipped with the BLAS kernel of the machine).
    """
    evidence = float(f.patch_area[prob > 0.5].sum())
    faces_of_break = _evidence_regions(f, prob > 0.5)
    weight = params.smoothness
    for _ in range(4):
        label = _graph_cut(f, prob, params, weight=weight)
        if (abs(float(f.patch_area[label].sum()) - evidence) <= 0.5 * evidence
                and all(f.patch_area[r & label].sum() >= 0.5 * f.patch_area[r].sum() for r in faces_of_break)):
            return label
        weight *= 0.5
    return prob > 0.5


def _evidence_regions(f: _Fragment, evidence: np.ndarray) -> list[np.ndarray]:
    """Masks (patches,) of the connected regions of fracture evidence at least a quarter the
    area of the largest: the fragment's break faces. Specks of evidence far smaller than
    the fragment's main break face are what the graph cut is for, and are not returned."""
    pu, pv = f.patch[f.pairs[:, 0]], f.patch[f.pairs[:, 1]]
    both = evidence[pu] & evidence[pv] & (pu != pv)
    _, comp = connected_components(len(evidence), np.column_stack([pu[both], pv[both]]))
    ids = np.unique(comp[evidence])
    areas = np.array([f.patch_area[(comp == c) & evidence].sum() for c in ids])
    if not len(ids):
        return []
    return [(comp == c) & evidence for c, a in zip(ids, areas) if a >= 0.25 * areas.max()]


def _fracture_components(gmm, scores: np.ndarray, weights: np.ndarray, *, min_share: float) -> tuple[list[int], float]:
    """The mixture components that are fracture, and the share of the area they take.

    Parameters
    ----------
    gmm : fitted 1-d ``GaussianMixture`` of the patch scores (rougher is higher)
    scores, weights : (p,) patch scores and areas the share is measured on
    min_share : a break is not a sliver: below this share the next roughest joins
    """
    means, sds = gmm.means_[:, 0], np.sqrt(gmm.covariances_.ravel())
    order = np.argsort(means)
    rough = [int(order[-1])]
    if len(order) == 3 and means[order[2]] - means[order[1]] < MERGE_SDS * min(sds[order[2]], sds[order[1]]):
        # the middle component overlaps the roughest: one kind of fracture split in two.
        # Judged by nearness of the means alone, noisy original surface spread over two
        # components joined the break; within the wider of the two sds, a broad roughest
        # component swallowed a narrow middle one of original surface
        rough.append(int(order[1]))
    # when the roughest component holds a tiny share of the area it is the rims and spikes
    # of a noisy surface and the fracture lies in the next one
    while True:
        share = float(np.average(gmm.predict_proba(scores[:, None])[:, rough].sum(axis=1) > 0.5, weights=weights))
        if share >= min_share or len(rough) == len(order) - 1:
            return rough, share
        rough.append(int(order[-1 - len(rough)]))


def _graph_cut(f: _Fragment, prob: np.ndarray, params: SegmentParams, *, weight: float) -> np.ndarray:
    """(patches,) bool: the minimum cut of patch evidence plus smooth-boundary length."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order, maximum_flow

    k = len(prob)
    prob = np.clip(prob, 1e-3, 1 - 1e-3)
    pu, pv = f.patch[f.pairs[:, 0]], f.patch[f.pairs[:, 1]]
    cross = pu != pv
    smooth = f.edge_length[cross] * np.exp(-((f.dihedral[cross] / params.smooth_angle) ** 2))
    # evidence is an area, the boundary a length: scale the boundary by the typical patch size
    total = f.patch_area.sum()
    boundary = weight * smooth * np.sqrt(total)
    cost_fracture = -np.log(prob) * f.patch_area
    cost_original = -np.log(1 - prob) * f.patch_area
    unit = 1e6 / total  # maximum_flow needs integer capacities
    source, sink = k, k + 1
    rows = np.concatenate([pu[cross], pv[cross], np.full(k, source), np.arange(k)])
    cols = np.concatenate([pv[cross], pu[cross], np.arange(k), np.full(k, sink)])
    caps = np.concatenate([boundary, boundary, cost_original, cost_fracture]) * unit
    graph = coo_matrix((np.rint(caps).astype(np.int64), (rows, cols)), shape=(k + 2, k + 2)).tocsr()
    flow = maximum_flow(graph, source, sink).flow
    residual = graph - flow
    residual.data[residual.data < 0] = 0
    residual.eliminate_zeros()
    reach = breadth_first_order(residual, source, directed=True, return_predecessors=False)
    label = np.zeros(k, bool)
    label[reach[reach < k]] = True
    return label
