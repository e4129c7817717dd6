"""Real spherical harmonics, degrees 0-3, in the INRIA 3DGS basis and coefficient order: the
constants and the basis terms, written once for torch tensors (splatting.gaussians.sh) and numpy
arrays (the Blender add-on, which must not import torch).  Plain arithmetic on x, y, z, so either
array type goes through the same expressions in the same order (the same bits).
"""

C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
      -0.4570457994644658, 1.445305721320277, -0.5900435899266435)


def sh_terms(x, y, z, const, degree):
    """The (degree+1)**2 basis values Y_k(d) of unit directions d = (x, y, z), as a list;
    `const` is Y_0 = C0 shaped like x (torch.full_like / np.full_like, the caller's array type)."""
    out = [const]
    if degree >= 1:
        out += [-C1 * y, C1 * z, -C1 * x]
    if degree >= 2:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        out += [C2[0] * xy, C2[1] * yz, C2[2] * (2 * zz - xx - yy), C2[3] * xz, C2[4] * (xx - yy)]
    if degree >= 3:
        out += [C3[0] * y * (3 * xx - yy), C3[1] * xy * z, C3[2] * y * (4 * zz - xx - yy),
                C3[3] * z * (2 * zz - 3 * xx - 3 * yy), C3[4] * x * (4 * zz - xx - yy),
                C3[5] * z * (xx - yy), C3[6] * x * (xx - 3 * yy)]
    return out
