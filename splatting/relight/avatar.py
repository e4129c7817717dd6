"""A relightable rider: the skinned avatar plus each Gaussian's albedo, gloss and normal.

The relight channels are fitted on the avatar's own rest-pose ring views (their albedo/normal/gloss
passes, `python -m splatting relight-fit --views AVATAR/views --ply AVATAR/rider.ply`) and stored
beside rider.ply as rider.relight.npz.  Posing turns each normal with the Gaussian's skinning
rotation (RiderAvatar.pose_tensors' "rotations": the bone's rotation, or the polar factor of the
blended bones), the same rotation that turns its covariance.
"""
import os

import torch

from cyclist_formats import bike_folder
from splatting.gaussians.container import Gaussians
from splatting.relight.render import relit_static
from splatting.relight.shading import ROUGHNESS
from splatting.rider.avatar import PLY_NAME, RiderAvatar

# the roster riders' material (addon/core/rider/rider_import.py): a fully rough dielectric
RIDER_ROUGHNESS = 1.0


class RelightableAvatar:
    def __init__(self, avatar: RiderAvatar, albedo, normals, gloss):
        n = len(avatar)
        if any(tuple(x.shape) != (n, 3) for x in (albedo, normals, gloss)):
            raise ValueError(f"relight channels {tuple(albedo.shape)} / {tuple(normals.shape)} / "
                             f"{tuple(gloss.shape)} != ({n}, 3)")
        self.avatar = avatar
        self.albedo, self.normals, self.gloss = albedo.float(), normals.float(), gloss.float()
        self.static = relit_static(self.albedo, self.gloss)  # render_relit(..., static=): pose-invariant

    @classmethod
    def load(cls, folder):
        return cls.of(RiderAvatar.load(folder), folder)

    @classmethod
    def of(cls, avatar, folder):
        """The relight channels of folder's avatar (PLY_NAME's .relight.npz) for its loaded avatar."""
        path = os.path.join(folder, PLY_NAME)
        r = bike_folder.read_relight(path, n=len(avatar))
        if bike_folder.RELIGHT_VIEW_KEY in r:  # posing turns normals by skinning only: refuse, not drop
            raise bike_folder.UserError(f"{bike_folder.relight_path(path)}: view-dependent normals are for bikes' "
                                        "parts; fit the avatar without --view-normals")
        return cls(avatar, *(torch.from_numpy(r[k]) for k in ("albedo", "normal", "gloss")))

    def posed_normals(self, rotations):
        """(..., N, 3, 3) skinning rotations (RiderAvatar.pose_tensors' "rotations") -> (..., N, 3) normals."""
        return (rotations @ self.normals[..., None]).squeeze(-1)

    def pose(self, local_rotmats, root_trans=None):
        """(B, 24, 3, 3), (B, 3) -> list of B (Gaussians, albedo, world normals, gloss)."""
        out = self.avatar.pose_tensors(local_rotmats, root_trans)
        g = self.avatar.gaussians
        normals = self.posed_normals(out["rotations"])
        return [(Gaussians(out["means"][b], out["quats"][b], g.log_scales, g.opacity_logits, out["sh"][b]),
                 self.albedo, normals[b], self.gloss) for b in range(local_rotmats.shape[0])]


def cyclist_static(rb, ra=None):
    """The pose-invariant relight channels of a cyclist, the bike's Gaussians first, then the
    rider's: (albedo (N, 3), gloss (N, 3), roughness (N,), sky visibility (N,)).  The bike keeps
    shading.ROUGHNESS and its own sky visibility (RelightableBike.sky_visibility); a rider has
    RIDER_ROUGHNESS and the whole sky (rider_relit's model)."""
    alb, gl = [rb.albedo], [rb.gloss]
    rough, sky = [torch.full((len(rb.albedo),), ROUGHNESS)], [rb.sky_visibility()]
    if ra is not None:
        alb.append(ra.albedo)
        gl.append(ra.gloss)
        rough.append(torch.full((len(ra.albedo),), float(RIDER_ROUGHNESS)))
        sky.append(torch.ones(len(ra.albedo)))
    return tuple(torch.cat(x) for x in (alb, gl, rough, sky))
