"""Forward kinematics over only the joints between the root and the IK's end-effectors, built
once per solve: the hot loop of the optimiser."""
import torch

from splatting.rider.ik.slots import SLOT_JOINTS
from splatting.rider.kinematics import JOINT_INDEX, PARENTS


class ReducedChain:
    """FK over only the joints on a path root -> end-effector, with free rotations from the
    parameter slots and constant joints between two kept joints folded into (C, d):
    R_world[j] = R_world[a] @ C_j @ L_j,  pos[j] = pos[a] + R_world[a] @ d_j  (a = kept ancestor).
    Kept joints are processed by depth, one batched matmul per level."""

    def __init__(self, rest, init_R, effectors):
        B = init_R.shape[0]
        slot = {JOINT_INDEX[n]: i for i, n in enumerate(SLOT_JOINTS)}
        eff = [JOINT_INDEX[n] for n in effectors]

        def ancestors(j):
            out = []
            while PARENTS[j] >= 0:
                j = PARENTS[j]
                out.append(j)
            return out

        anc_of_eff = {a for e in eff for a in ancestors(e)}
        keep = sorted({0} | set(eff) | {j for j in slot if j in anc_of_eff})
        kparent, depth, has_child = {}, {0: 0}, set()
        for j in keep[1:]:
            a = next(x for x in ancestors(j) if x in keep)
            kparent[j], depth[j] = a, depth[a] + 1
            has_child.add(a)
        off = rest.clone()
        off[1:] = rest[1:] - rest[list(PARENTS[1:])]
        eye = torch.eye(3, dtype=rest.dtype).expand(B, 3, 3)
        carried = {0: 0}  # joint -> row in the previous level's carried (R, pos), i.e. joints with kept children
        col, ncols = {0: 0}, 1  # joint -> column in the concatenation of every level's positions
        self.levels = []
        for lev in range(1, max(depth.values(), default=0) + 1):
            nodes = [j for j in keep if depth[j] == lev]
            pidx, Cs, ds, slots, rows = [], [], [], [], []
            for k, j in enumerate(nodes):
                path = [j]
                while PARENTS[path[-1]] != kparent[j]:
                    path.append(PARENTS[path[-1]])
                C, d = eye, torch.zeros(B, 3, dtype=rest.dtype)
                for p in path[::-1]:  # from the kept ancestor's child down to j
                    d = d + (C @ off[p])
                    if p != j:
                        C = C @ init_R[:, p]
                if j in has_child:
                    if j in slot:
                        slots.append(slot[j])
                    else:  # a constant joint with kept children: its rotation goes into C
                        C = C @ init_R[:, j]
                        slots.append(len(SLOT_JOINTS))  # the identity slot
                    rows.append(k)
                    Cs.append(C)
                pidx.append(carried[kparent[j]])
                ds.append(d)
                col[j] = ncols + k
            ncols += len(nodes)
            self.levels.append(dict(
                pidx=torch.tensor(pidx), d=torch.stack(ds, 1)[..., None].float(),
                C=torch.stack(Cs, 1).float() if Cs else None, slots=torch.tensor(slots, dtype=torch.long),
                rows=None if rows == list(range(len(nodes))) else torch.tensor(rows, dtype=torch.long),
                carry=bool(rows)))
            carried = {nodes[k]: r for r, k in enumerate(rows)}
        self.rest_root = rest[0].float()
        self.needs_identity = any(L["carry"] and int(L["slots"].max()) == len(SLOT_JOINTS) for L in self.levels)
        self.eff_cols = torch.tensor([col[j] for j in eff])

    def rows(self, ix):
        """The same chain for the batch rows ix (a LongTensor): what solve continues on."""
        out = object.__new__(ReducedChain)
        out.__dict__.update(self.__dict__)
        out.levels = [dict(L, d=L["d"][ix], C=None if L["C"] is None else L["C"][ix]) for L in self.levels]
        return out

    def __call__(self, rot, trans):
        """rot (B, 12, 3, 3) slot rotations, trans (B, 3) -> effector positions (B, E, 3)."""
        if self.needs_identity:
            rot = torch.cat([rot, torch.eye(3, dtype=rot.dtype).expand(rot.shape[0], 1, 3, 3)], 1)
        Rw = rot[:, :1]  # the root's world rotation (B, 1, 3, 3)
        pos = (self.rest_root + trans)[:, None]  # the root rotates about itself
        all_pos = [pos]
        for L in self.levels:
            Rp = Rw[:, L["pidx"]]
            pos = pos[:, L["pidx"]] + (Rp @ L["d"])[..., 0]
            all_pos.append(pos)
            if L["carry"]:
                if L["rows"] is not None:
                    Rp, pos = Rp[:, L["rows"]], pos[:, L["rows"]]
                Rw = Rp @ (L["C"] @ rot[:, L["slots"]])
        return torch.cat(all_pos, 1)[:, self.eff_cols]
