"""The split of the shared meshes by *mesh*: the one place that says which mesh may be trained on.

A U-Net that is scored on frames of meshes it trained on measures memory, not generalisation, so
the corpus splits whole meshes (never frames) into train / val / test. Every mesh of
``../shared/assets/meshes`` (its SOURCES.tsv) is in exactly one split. Interiors (rooms a camera
fits inside) are listed apart from objects: the scene composer (:mod:`neuralao.pipeline.geometry.compose`)
places objects, while interiors are scenes of their own.

* **test** holds what the issue asks the shipped model to be judged on: glTF game assets
  (KnightArmor, RetroUFO, CesiumMilkTruck), dense scans (Lucy, the horse) and a low-poly interior
  (the Cornell box).
* **val** holds one of each kind again (a scan, a CAD part, glTF props, a character, a dense
  interior) so model selection sees the same variety.
* Sponza and sponza_partial are the same atrium (the partial OBJ is a truncated copy of it), so
  they share a split.
* The glTF props added to the shared meshes later (thin strands, shells, small objects in contact)
  all train: val and test stay as they were, so earlier scores still compare. They joined at pool
  revision 2 (:data:`ADDED`): a composed scene draws from its split's pool at the revision its
  settings name, so adding meshes here never changes the scenes of an existing config.
"""

from __future__ import annotations

from typing import Literal

from neuralao.runtime.foundation.errors import NeuralaoError

Split = Literal["train", "val", "test"]

# Object meshes that joined a split after the first corpus, by the pool revision they joined at
# (revision 1: every other object mesh). See object_meshes.
ADDED: dict[int, tuple[str, ...]] = {
    # glTF props with thin parts, open shells and small objects in contact (all train)
    2: (
        "Avocado",
        "ClearcoatWicker",
        "GlassBrokenWindow",
        "GlassHurricaneCandleHolder",
        "IridescenceLamp",
        "IridescentDishWithOlives",
        "LightsPunctualLamp",
        "MosquitoInAmber",
        "WaterBottle",
    ),
}
LATEST_POOL = max(ADDED)

# Train-split meshes of the first corpus that the larger corpus (configs/corpus-large.json) and every
# model trained on it leave out: no frame of theirs is trained or validated on, no budget or width is
# chosen by them, so `neuralao evaluate` can score meshes nobody here tuned for (a scan, a CAD body, a
# glTF prop, a thin wicker structure). They keep their split for the first corpus's configs.
HELD_ASIDE: tuple[str, ...] = ("Corset", "beetle", "Spaceship", "ClearcoatWicker")

# Object meshes, by split (bare names under neuralao.pipeline.geometry.scene.mesh_root()).
OBJECTS: dict[str, tuple[str, ...]] = {
    "train": (
        "bunny",
        "dragon",
        "spot",
        "teapot",
        "rocker-arm",
        "suzanne",
        "cow",
        "beetle",
        "2CylinderEngine",
        "ReciprocatingSaw",
        "FlightHelmet",
        "BrainStem",
        "Spaceship",
        "SheenChair",
        "GlamVelvetSofa",
        "StainedGlassLamp",
        "ToyCar",
        "BoomBox",
        "Corset",
        "MaterialsVariantsShoe",
        "CesiumMan",
        "Fox",
        "BarramundiFish",
        *ADDED[2],
    ),
    "val": ("happy_buddha", "fandisk", "AnisotropyBarnLamp", "GlassVaseFlowers", "RiggedFigure"),
    "test": ("lucy", "horse", "KnightArmor", "RetroUFO", "CesiumMilkTruck"),
}

# Interiors (camera inside), by split.
INTERIORS: dict[str, tuple[str, ...]] = {
    "train": ("Sponza", "sponza_partial"),
    "val": ("CountryKitchen",),
    "test": ("cornell_box",),
}


def object_meshes(split: str, revision: int = LATEST_POOL) -> tuple[str, ...]:
    """The object meshes of ``split`` ("train", "val" or "test") at pool ``revision`` (those that had
    joined by then; the latest: all of them): what the composer may place."""
    if split not in OBJECTS:
        raise NeuralaoError(f"unknown split {split!r}; use one of {', '.join(OBJECTS)}")
    if not 1 <= revision <= LATEST_POOL:
        raise NeuralaoError(f"mesh pool revision must lie in [1, {LATEST_POOL}], got {revision}")
    later = {m for r, names in ADDED.items() if r > revision for m in names}
    return tuple(m for m in OBJECTS[split] if m not in later)


def split_of(mesh: str) -> str | None:
    """The split of a bare mesh name, or None for a mesh outside the table (a user's own file)."""
    for table in (OBJECTS, INTERIORS):
        for split, names in table.items():
            if mesh in names:
                return split
    return None


def all_meshes() -> dict[str, str]:
    """Every listed mesh -> its split."""
    return {m: s for table in (OBJECTS, INTERIORS) for s, names in table.items() for m in names}
