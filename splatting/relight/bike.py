"""A relightable bike: the parametric BikeModel plus each part's albedo and normals, posed together.

Normals are directions, so a part's pose turns them with its rotation only (the R of H_g H_s for
steering, H_g H_p for the crank, H_g for the frame; docs/contract.md), never its translation.
"""
import torch

from cyclist_formats import bike_folder
from splatting.bike.model import BikeModel
from splatting.relight.render import relit_static
from splatting.relight import shadow  # shadow.X at call time: the maps are swapped in tests


class RelightableBike:
    def __init__(self, model: BikeModel, albedo, normals, gloss=None, normal_view=None):
        """albedo, normals, gloss: (N, 3) in the model's Gaussian order (model.part_names, model.ranges);
        normal_view: None, or (N, 3, 3) view-dependent normals in the parts' frames (render.view_normals)."""
        gloss = torch.zeros_like(albedo) if gloss is None else gloss
        if any(x.shape != (len(model), 3) for x in (albedo, normals, gloss)):
            raise ValueError(f"albedo {tuple(albedo.shape)} / normals {tuple(normals.shape)} / gloss "
                             f"{tuple(gloss.shape)} != ({len(model)}, 3)")
        if normal_view is not None and normal_view.shape != (len(model), 3, 3):
            raise ValueError(f"normal_view {tuple(normal_view.shape)} != ({len(model)}, 3, 3)")
        self.normal_view = None if normal_view is None else normal_view.float()
        self.model = model
        self.albedo = albedo.float()
        self.gloss = gloss.float()
        self.normals = normals.float()
        self._sky = None
        self.static = relit_static(self.albedo, self.gloss)  # render_relit(..., static=): pose-invariant

    @classmethod
    def load(cls, bike_dir):
        return cls.of(BikeModel.load(bike_dir), bike_dir)

    @classmethod
    def of(cls, model, bike_dir):
        """The relight channels of bike_dir's parts (gaussians/PART.relight.npz) for its loaded model."""
        parts = [bike_folder.read_relight(bike_folder.gaussians_path(bike_dir, name), n=e - a)
                 for name, (a, e) in zip(model.part_names, model.ranges)]
        cat = lambda k: torch.cat([torch.from_numpy(p[k]) for p in parts])  # noqa: E731
        view = None
        if any(bike_folder.RELIGHT_VIEW_KEY in p for p in parts):  # a part fitted without: view-independent
            view = torch.cat([torch.from_numpy(p[bike_folder.RELIGHT_VIEW_KEY]) if bike_folder.RELIGHT_VIEW_KEY in p
                              else torch.zeros(len(p["normal"]), 3, 3) for p in parts])
        return cls(model, cat("albedo"), cat("normal"), cat("gloss"), view)

    def posed_normals(self, pose):
        """(8,) pose -> world-frame normals (N, 3)."""
        T = self.model.part_transforms(pose)
        out = torch.empty_like(self.normals)
        for name, (a, e) in zip(self.model.part_names, self.model.ranges):
            R = T[name][0, :3, :3].to(self.normals.dtype)
            out[a:e] = self.normals[a:e] @ R.T
        return out

    def posed_normal_view(self, pose):
        """(8,) pose -> world-frame normal_view (N, 3, 3) (R B R^T per part), for render_relit(normal_view=);
        None for a bike fitted without view-dependent normals."""
        if self.normal_view is None:
            return None
        T = self.model.part_transforms(pose)
        out = torch.empty_like(self.normal_view)
        for name, (a, e) in zip(self.model.part_names, self.model.ranges):
            R = T[name][0, :3, :3].to(self.normal_view.dtype)
            out[a:e] = R @ self.normal_view[a:e] @ R.T
        return out

    def pose(self, pose):
        """(8,) pose -> (PosedBike, albedo (N, 3), world normals (N, 3), gloss (N, 3))."""
        return self.model.pose(pose), self.albedo, self.posed_normals(pose), self.gloss

    def sky_visibility(self):
        """(N,) each Gaussian's share of a uniform sky (splatting/relight/shadow.py sky_visibility),
        computed once at the rest pose (zero pose, canonical normals) and kept: a uniform sky does
        not care where the bike is turned, and steering and crank angles barely change what the
        bike hides from itself (on the demo's city bike the rest pose's values scored 28.62 dB at
        bench/relight.py's poses, each pose's own 28.60)."""
        if self._sky is None:

            g = self.model.pose(torch.zeros(8, dtype=torch.float64)).gaussians
            self._sky = shadow.sky_visibility(g.map(lambda x: x.contiguous()), self.normals,
                                       antialiased=self.model.antialiased, eps2d=self.model.eps2d)  # drawn as trained
        return self._sky
