"""The match-pairs stage: every pair of fragments registered, in a process pool.

:func:`registration_params` resolves the registration options from the data (the contact
tolerance from the vertex noise, more hypotheses for thin-walled sherds); :func:`match_set`
registers every pair and measures how far apart mating surfaces are.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from .features import same_surface
from .geometry import make_scene
from .parallel import pool_map, worker_state
from .prepare import PreparedFragment, set_noise, thin_walled
from .registration import RegistrationParams, register_pair, set_gap, with_noise

log = logging.getLogger(__name__)


def registration_params(fragments: list[PreparedFragment], *, size: float, params=None):
    """The registration options for this set, resolved from the data: ``params`` (default
    ``RegistrationParams()``) with the contact tolerance raised to cover its vertex noise."""
    params = with_noise(params or RegistrationParams(), noise=set_noise(fragments), size=size)
    if thin_walled(fragments):
        # one-point hypotheses on strips are many and their local consensus weak (a break
        # curve matches any curve over a short stretch): more of them go on to ICP
        params = dataclasses.replace(params, shortlist=params.shell_shortlist + params.shell_whole,
                                     consensus_pool=params.shell_consensus_pool)
    return params


@dataclass
class PairMemo:
    """Pair registrations already made in a run, for its retries to reuse.

    A retry segments the set again and registers every pair again; a pair whose two
    fragments' matched surfaces (:class:`features.FractureSurface`) are unchanged would be
    registered exactly as before (same surfaces, meshes, options and the pair's own random
    stream), so its result is taken from here instead. Entries are keyed by the pair and the
    options and checked against both surfaces, array by array; every segmentation's are
    kept (a later retry may start again from an earlier one's labels).
    """

    entries: dict = field(default_factory=dict)  # (i, j, params) -> [(surface i, surface j, PairResult)]

    def get(self, i: int, j: int, params, surfaces: list):
        for a, b, result in self.entries.get((i, j, params), ()):
            if same_surface(a, surfaces[i]) and same_surface(b, surfaces[j]):
                return result
        return None

    def put(self, i: int, j: int, params, surfaces: list, result) -> None:
        self.entries.setdefault((i, j, params), []).append((surfaces[i], surfaces[j], result))


def _pair_worker_init(surfaces, meshes, size, params) -> None:
    worker_state.clear()
    worker_state.update(surfaces=surfaces, meshes=meshes, size=size, params=params, scenes={})


def _pair_worker(task):
    i, j, rng = task
    w = worker_state
    scenes = w["scenes"]
    for k in (i, j):
        if k not in scenes:
            scenes[k] = make_scene(*w["meshes"][k])
    return (i, j), register_pair(w["surfaces"][i], w["surfaces"][j], source_scene=scenes[i], target_scene=scenes[j],
                                 size=w["size"], params=w["params"], rng=rng)


def _pair_index(i: int, j: int, n: int) -> int:
    """The place of pair (min, max) among all pairs (0, 1), (0, 2), ..., (n - 2, n - 1)."""
    a, b = min(i, j), max(i, j)
    return a * n - a * (a + 1) // 2 + b - a - 1


def match_pairs(
    fragments: list[PreparedFragment],
    *,
    size: float,
    pairs: list[tuple[int, int]] | None = None,
    params=None,
    seed: int = 0,
    jobs: int = 1,
    scheduler: str | None = None,
    progress: bool = False,
    memo: PairMemo | None = None,
) -> dict[tuple[int, int], object]:
    """Register fragment pairs (all, or the given (source, target) index pairs): PairResult per pair.

    ``jobs`` > 1 registers pairs in that many processes; every pair has its own random
    stream (spawned from ``seed``, the pair's place among all pairs), so results do not
    depend on ``jobs``, nor on the other pairs registered, nor
    on ``scheduler`` (the address of a Dask cluster to register them on instead).
    ``params``: default :func:`registration_params` of the fragments (noise-aware tolerance).
    ``memo``: registrations made earlier in the run (:class:`PairMemo`), reused where
    nothing a pair depends on has changed, and the new ones added to it.
    """
    params = params or registration_params(fragments, size=size)
    n = len(fragments)
    if pairs is None:
        pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    # every pair's stream is the one it has among all pairs in order, registered or not: a
    # result never depends on which other pairs were registered
    # (the k-th child of SeedSequence(seed).spawn, made alone: its spawn key is (k,))
    rngs = [np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(_pair_index(i, j, n),))))
            for i, j in pairs]
    surfaces = [f.surface for f in fragments]
    results = {}
    if memo is not None:
        for i, j in pairs:
            if (hit := memo.get(i, j, params, surfaces)) is not None:
                results[(i, j)] = hit
        if results:
            log.info("%d of %d pairs unchanged since an earlier registration: reused", len(results), len(pairs))
    tasks = [(i, j, rng) for (i, j), rng in zip(pairs, rngs) if (i, j) not in results]
    init = (surfaces, [f.mesh for f in fragments], size, params)
    for key, res in tqdm(pool_map(_pair_worker, tasks, jobs=jobs, scheduler=scheduler, initializer=_pair_worker_init,
                                  initargs=init),
                         total=len(tasks), desc="pairs", disable=not progress):
        results[key] = res
        if memo is not None:
            memo.put(*key, params, surfaces, res)
    return {pair: results[pair] for pair in pairs}


def match_set(
    fragments: list[PreparedFragment], *, size: float, params, gap: float | None = None, seed: int = 0,
    pairs: list[tuple[int, int]] | None = None, jobs: int = 1, scheduler: str | None = None, progress: bool = False,
    memo: PairMemo | None = None,
):
    """Register every pair (or the given ones), with the separation of mating surfaces measured or given.

    With ``gap`` None, the pairs are registered touching, the separation of the touching
    ones measured (:func:`registration.set_gap`), and when it exceeds the contact
    tolerance (plain contacts would close it, shifting every piece by it and counting
    rough surfaces as interpenetrating), every pair is registered again that far apart.

    Returns
    -------
    results : (source, target) -> PairResult
    params : the RegistrationParams used, ``gap`` resolved (fraction of ``size``)
    """
    if gap is not None:
        params = dataclasses.replace(params, gap=float(gap))
    results = match_pairs(fragments, size=size, params=params, pairs=pairs, seed=seed, jobs=jobs,
                          scheduler=scheduler, progress=progress, memo=memo)
    if gap is None:
        measured = set_gap([f.surface for f in fragments], results, size=size, params=params)
        if measured > params.tolerance:
            log.info("mating surfaces are %.3g x size apart (material lost at the break?): matching again with "
                     "that gap", measured)
            params = dataclasses.replace(params, gap=measured)
            results = match_pairs(fragments, size=size, params=params, pairs=pairs, seed=seed, jobs=jobs,
                                  scheduler=scheduler, progress=progress, memo=memo)
    return results, params

