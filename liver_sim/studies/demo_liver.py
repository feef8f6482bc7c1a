"""The liver a demo runs on: the default liver or a user's mesh, and the parameters that make the physics
node load it and the simulated hand press its top."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from liver_sim.mesh.anatomical_support import read_support, support_path
from liver_sim.mesh.io import load_mesh
from liver_sim.mesh.landmarks import press_anchor
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.mesh.tetmesh import TetMesh
from liver_sim.physics.parameters import PARAMETERS as PHYSICS_PARAMETERS
from liver_sim.physics.settings import ModelParams
from liver_sim.tool.scripts import ScriptSettings


@dataclass(frozen=True)
class DemoMesh:
    """The liver a demo runs on: `path` None for the default liver, else a mesh file whose coordinates ×
    `scale` are metres, loaded as the physics node loads it (mesh_path, mesh_scale, target_tets)."""

    path: Path | None = None
    scale: float = 1.0

    @property
    def name(self) -> str:
        """What titles call it: "default liver" or the file's name."""
        return "default liver" if self.path is None else self.path.name

    @property
    def title(self) -> str:
        """`name` at the start of a title."""
        return self.name[:1].upper() + self.name[1:]

    def load(self) -> TetMesh:
        """The mesh in metres; MeshError (a ValueError naming the file) when refused."""
        if self.path is None:
            return default_liver()
        return load_mesh(self.path, PHYSICS_PARAMETERS["target_tets"].default, self.scale)

    def support(self) -> dict:
        """The physics' `support` and `support_regions` from the support file beside the mesh (one built from a
        segmentation has one: mesh.anatomical_support), or none (the defaults)."""
        if self.path is None or not support_path(self.path).is_file():
            return {}
        return read_support(support_path(self.path))

    def model_params(self) -> ModelParams:
        """The model's settings for this mesh: the defaults, with the support file's regions when it has one."""
        support = self.support()
        if not support:
            return ModelParams()
        regions = support["support_regions"]
        return ModelParams(support=support["support"],
                           support_regions=tuple(tuple(regions[i:i + 5]) for i in range(0, len(regions), 5)))

    def physics_parameters(self, mesh: TetMesh) -> dict:
        """The physics node's parameters that load this mesh and its support file (none for the default liver)."""
        if self.path is None:
            return {}
        return {"mesh_path": str(self.path.resolve()), "mesh_scale": self.scale, **self.support()}

    def device_parameters(self, mesh: TetMesh) -> dict:
        """The script anchor and device map that make the simulated hand press the top of `mesh` with the
        same device-frame moves as on the default liver (none for the default liver)."""
        if self.path is None:
            return {}
        anchor = press_anchor(mesh)
        shift = anchor - np.asarray(ScriptSettings().anchor_m)  # the device origin follows the press point
        return {"anchor_m": [round(float(v), 6) for v in anchor],
                "device_translation_m": [round(float(v), 6) for v in shift]}
