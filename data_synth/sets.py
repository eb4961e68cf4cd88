"""The regression puzzle sets, as lists of specs built from seeds (nothing large is committed).

smoke: three small meshes of different character, 2-5 pieces; seconds to build, used by tests.
bench: six meshes (smooth organic, thin parts, sharp CAD edges, genus > 0) x {2, 4, 8, 12, 20}
pieces x three seeds, plus scan-noise variants; used by benchmarks.
sherds: the thin-walled pot x {4, 8, 12} pieces x three seeds, plus scan-noise variants.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class PuzzleSpec:
    """One puzzle: a bundled mesh broken with ``reassemble break`` options."""

    mesh: str
    pieces: int
    seed: int
    noise: float = 0.0
    chips: float = 0.0
    decimate: float = 0.0

    @property
    def name(self) -> str:
        extra = ""
        if self.noise:
            extra += f"_noise{self.noise:g}"
        if self.chips:
            extra += f"_chips{self.chips:g}"
        if self.decimate:
            extra += f"_dec{self.decimate:g}"
        return f"{self.mesh}_{self.pieces:02d}p_s{self.seed}{extra}"


# name -> character, for reports
BENCH_MESHES = {
    "spot": "smooth organic",
    "fish_low_resolution": "smooth organic, low resolution",
    "torus": "genus 1",
    "wingnut": "thin parts",
    "angle_block": "sharp CAD edges",
    "featuretype": "sharp CAD edges, genus 9",
}


def smoke_set() -> list[PuzzleSpec]:
    return [
        PuzzleSpec("spot_low_resolution", 2, 0),
        PuzzleSpec("spot_low_resolution", 4, 1),
        PuzzleSpec("torus", 3, 0),
        PuzzleSpec("torus", 5, 2),
        PuzzleSpec("angle_block", 2, 0),
        PuzzleSpec("angle_block", 4, 3),
    ]


def bench_set(*, seeds: tuple[int, ...] = (0, 1, 2), noise: float = 0.001) -> list[PuzzleSpec]:
    clean = [
        PuzzleSpec(mesh, pieces, seed)
        for mesh in BENCH_MESHES
        for pieces in (2, 4, 8, 12, 20)
        for seed in seeds
    ]
    noisy = [
        PuzzleSpec(mesh, pieces, seeds[0], noise=noise)
        for mesh in BENCH_MESHES
        for pieces in (2, 4, 8, 12, 20)
    ]
    return clean + noisy


def sherds_set(*, seeds: tuple[int, ...] = (0, 1, 2), noise: float = 0.001) -> list[PuzzleSpec]:
    """Thin walls: the bundled vase (data_synth.shapes.vase_mesh), whose breaks are strips."""
    clean = [PuzzleSpec("vase", pieces, seed) for pieces in (4, 8, 12) for seed in seeds]
    return clean + [PuzzleSpec("vase", pieces, seeds[0], noise=noise) for pieces in (4, 8, 12)]


SETS = {"smoke": smoke_set, "bench": bench_set, "sherds": sherds_set}
