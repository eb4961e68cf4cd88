"""The regression puzzle sets, as lists of specs built from seeds (nothing large is committed).

smoke: three small meshes of different character, 2-5 pieces; seconds to build, used by tests.
bench: six meshes (smooth organic, thin parts, sharp CAD edges, genus > 0) x {2, 4, 8, 12, 20}
pieces x three seeds, plus scan-noise variants; used by benchmarks.
sherds: the thin-walled pot x {4, 8, 12} pieces x three seeds, plus scan-noise variants.
field-tuning, field-validation: every fracture style x meshes of every kind (smooth and
detailed organic, CAD, thin parts, sherds) x 2-20 pieces, clean and with scan noise, split
by mesh into a half to tune on and a half to report (see :data:`FIELD_MESHES`). Their
meshes come from the package and, for those whose license forbids bundling them, from a
folder given as ``--shared`` (holding ``data/meshes``; the project never looks for one itself).
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
    style: str = "fractal"
    roughness: float | None = None  # None: the style's default

    @property
    def name(self) -> str:
        extra = ""
        if self.style != "fractal":
            extra += f"_{self.style}"
        if self.roughness is not None:
            extra += f"_r{self.roughness:g}"
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


@dataclass(frozen=True)
class FieldMesh:
    """A mesh of the field sets: its kind, which half it is in, and where it comes from."""

    kind: str
    half: str  # "tuning" or "validation"
    source: str  # a bundled mesh name, "shared:<path under data/meshes>" or "shapes:<function>"
    why: str  # why it is in this half
    rotates: bool = True  # takes its turn at the 12- and 20-piece puzzles (False: joined after they were fixed)


FIELD_STYLES = ("fractal", "smooth", "cells", "mixed")
FIELD_KINDS = ("smooth organic", "detailed organic", "CAD", "thin parts", "sherds")

# Split by mesh: no mesh is in both halves, and each half has every kind. Within a kind the
# halves are matched: similar sizes and detail, the harder case of a pair alternating.
FIELD_MESHES = {
    # tuning half
    "spot": FieldMesh("smooth organic", "tuning", "spot", "the cow the pipeline was built on: known ground"),
    "torus": FieldMesh("smooth organic", "tuning", "torus", "genus 1, smooth; its cells run round the ring"),
    "boot": FieldMesh("detailed organic", "tuning", "boot",
                      "tread, stitching and lace loops: fine detail on a hollow shape, genus 12"),
    "ogre": FieldMesh("detailed organic", "tuning", "shared:ogre/ogre.ply",
                      "skin folds and teeth: the largest detailed figure, tuned on so it is not reported"),
    "falconstatue": FieldMesh("detailed organic", "tuning", "shared:falconstatue/falconstatue.ply",
                              "feather relief over a smooth body with a sharp plinth (relief like the lion's)"),
    "angle_block": FieldMesh("CAD", "tuning", "angle_block", "the CAD part of the old bench: planes and edges"),
    "adis16480": FieldMesh("CAD", "tuning", "adis16480", "housing with 24 holes: planes cut by many small holes"),
    "wingnut": FieldMesh("thin parts", "tuning", "wingnut", "thin wings on a hub: the thin part of the old bench"),
    "vase": FieldMesh("sherds", "tuning", "vase", "the pot of the sherds set: walls 2.5 % of its height"),
    "tile": FieldMesh("sherds", "tuning", "shapes:tile_mesh",
                      "a flat tile with a raised border (data_synth.shapes): flat sherds, CAD-like large triangles",
                      rotates=False),
    "flange": FieldMesh("CAD", "tuning", "shapes:flange_mesh",
                        "a flat ring with a bore collar, 8 bolt holes and a key notch (data_synth.shapes): "
                        "flat CAD rings, large triangles", rotates=False),
    # validation half
    "fish_low_resolution": FieldMesh("smooth organic", "validation", "fish_low_resolution",
                                     "smooth like the cow, coarse triangles (1.9k faces)"),
    "bunny": FieldMesh("smooth organic", "validation", "shared:bunny/bunny.obj",
                       "smooth remesh of a scan, never used for tuning"),
    "demosthenes": FieldMesh("detailed organic", "validation", "demosthenes",
                             "curly hair and beard: detail rougher than most breaks"),
    "lionstatue": FieldMesh("detailed organic", "validation", "shared:lionstatue/lionstatue.ply",
                            "mane and fur on a block base: relief like the falcon's, unseen"),
    "igea": FieldMesh("detailed organic", "validation", "shared:igea/igea.ply", "hair curls and chipped marble"),
    "horse": FieldMesh("detailed organic", "validation", "shared:horse/horse.ply",
                       "thin legs: detailed and thin at once"),
    "featuretype": FieldMesh("CAD", "validation", "featuretype", "genus 9, sharp edges, fillets"),
    "fixed_top": FieldMesh("CAD", "validation", "fixed_top", "flat ring with a notched rim, genus 7"),
    "octagonal_pocket": FieldMesh("thin parts", "validation", "octagonal_pocket",
                                  "a plate 7 % as thick as wide, pockets with thin walls"),
    "bowl": FieldMesh("sherds", "validation", "shapes:bowl_mesh",
                      "a wide open bowl (data_synth.shapes): sherds of another profile and wall"),
}

# inputs above this many faces are simplified (manifold3d, an error tolerance found by
# bisection) to about FIELD_TARGET_FACES before breaking: the fracture surfaces add ~10k
# faces a cut anyway, and the pipeline's time grows with the faces
FIELD_MAX_FACES = 30_000
FIELD_TARGET_FACES = 25_000


def field_set(half: str, *, noise: float = 0.001) -> list[PuzzleSpec]:
    """One half of the field set (``half`` "tuning" or "validation").

    Per mesh (i) and style (j): a small puzzle of 2, 3 or 4 pieces (by (i + j) mod 3),
    clean and with scan noise (same seed: the same cuts); per mesh one of 8 pieces (the
    style rotating); per style one of 12 pieces, and for fractal and cells one of 20 (the
    meshes that take turns rotating); on the
    detailed organic meshes a fractal break at roughness 0.01 in 4 pieces (smoother than
    the object's own surface).
    """
    meshes = [name for name, m in FIELD_MESHES.items() if m.half == half]
    rotating = [name for name in meshes if FIELD_MESHES[name].rotates]
    specs = []
    for i, mesh in enumerate(meshes):
        for j, style in enumerate(FIELD_STYLES):
            pieces = (2, 3, 4)[(i + j) % 3]
            specs.append(PuzzleSpec(mesh, pieces, 0, style=style))
            specs.append(PuzzleSpec(mesh, pieces, 0, noise=noise, style=style))
        specs.append(PuzzleSpec(mesh, 8, 1, style=FIELD_STYLES[i % len(FIELD_STYLES)]))
    for j, style in enumerate(FIELD_STYLES):
        specs.append(PuzzleSpec(rotating[(2 * j) % len(rotating)], 12, 2, style=style))
        if style in ("fractal", "cells"):  # two, not four: a 20-piece run takes ~10 minutes
            specs.append(PuzzleSpec(rotating[(2 * j + 1) % len(rotating)], 20, 2, style=style))
    for mesh in meshes:
        if FIELD_MESHES[mesh].kind == "detailed organic":
            specs.append(PuzzleSpec(mesh, 4, 1, roughness=0.01))
    return specs


SETS = {
    "smoke": smoke_set, "bench": bench_set, "sherds": sherds_set,
    "field-tuning": lambda: field_set("tuning"), "field-validation": lambda: field_set("validation"),
}
