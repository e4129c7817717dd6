"""3DArticCyclists torch side: Gaussian splatting on CPU, parametric bike, rider, datasets.

Never imports bpy.  Meets the Blender side only through files (docs/contract.md formats).
"""

import os as _os

# On the shared 2-core machine OpenMP's default spinning wait made 2 threads 5-8x slower than
# 1 (docs/rasterizer.md); passive waiting must be set before torch initialises OpenMP.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
