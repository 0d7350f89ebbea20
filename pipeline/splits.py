"""The split of the shared meshes by *mesh*: the one place that says which mesh may be trained on.

A U-Net that is scored on frames of meshes it trained on measures memory, not generalisation, so
the corpus splits whole meshes (never frames) into train / val / test. Every mesh of
``../shared/assets/meshes`` (its SOURCES.tsv) is in exactly one split. Interiors (rooms a camera
fits inside) are listed apart from objects: the scene composer (:mod:`pipeline.compose`) places
objects, while interiors are scenes of their own.

* **test** holds what the issue asks the shipped model to be judged on: glTF game assets
  (KnightArmor, RetroUFO, CesiumMilkTruck), dense scans (Lucy, the horse) and a low-poly interior
  (the Cornell box).
* **val** holds one of each kind again (a scan, a CAD part, glTF props, a character, a dense
  interior) so model selection sees the same variety.
* Sponza and sponza_partial are the same atrium (the partial OBJ is a truncated copy of it), so
  they share a split.
"""

from __future__ import annotations

from typing import Literal

from .errors import NeuralaoError

Split = Literal["train", "val", "test"]

# Object meshes, by split (bare names under pipeline.scene.mesh_root()).
OBJECTS: dict[str, tuple[str, ...]] = {
    "train": (
        "bunny", "dragon", "spot", "teapot", "rocker-arm", "suzanne", "cow", "beetle",
        "2CylinderEngine", "ReciprocatingSaw", "FlightHelmet", "BrainStem", "Spaceship",
        "SheenChair", "GlamVelvetSofa", "StainedGlassLamp", "ToyCar", "BoomBox", "Corset",
        "MaterialsVariantsShoe", "CesiumMan", "Fox", "BarramundiFish",
    ),
    "val": ("happy_buddha", "fandisk", "AnisotropyBarnLamp", "GlassVaseFlowers", "RiggedFigure"),
    "test": ("lucy", "horse", "KnightArmor", "RetroUFO", "CesiumMilkTruck"),
}  # fmt: skip

# Interiors (camera inside), by split.
INTERIORS: dict[str, tuple[str, ...]] = {
    "train": ("Sponza", "sponza_partial"),
    "val": ("CountryKitchen",),
    "test": ("cornell_box",),
}


def object_meshes(split: str) -> tuple[str, ...]:
    """The object meshes of ``split`` ("train", "val" or "test"): what the composer may place."""
    if split not in OBJECTS:
        raise NeuralaoError(f"unknown split {split!r}; use one of {', '.join(OBJECTS)}")
    return OBJECTS[split]


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
