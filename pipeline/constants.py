"""The one tolerance table (trimesh's ``tol`` habit). Tests and parity checks read from here.

Every entry says why it has the value it has. Monte-Carlo tolerances are in units of the
estimator's standard error where that is the natural scale.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Tolerances:
    # Monte-Carlo AO estimates vs closed forms: allowed |error| in standard errors
    # (binary: sqrt(p(1-p)/n)); 5 sigma keeps the false-failure rate below 1e-6 per check.
    mc_sigmas: float = 5.0
    # Absolute floor for MC comparisons when the variance is ~0 (fully open / fully closed).
    mc_abs_floor: float = 2e-3
    # pyrender G-buffer vs Embree primary rays: relative depth error (float32 depth buffer
    # interpolation on llvmpipe vs double-precision ray hit).
    gbuffer_depth_rel: float = 1e-4
    # ... cosine between G-buffer and Embree face normals.
    gbuffer_normal_cos: float = 0.999
    # ... fraction of foreground pixels whose triangle id may differ (edges where rasterisation
    # rules and ray-triangle tests legitimately disagree).
    gbuffer_id_mismatch_frac: float = 0.01
    # Generated GLSL vs onnxruntime, fp32 (issue targets).
    parity_mlp_fp32: float = 1e-5
    parity_unet_fp32: float = 1e-4
    # Generated GLSL with fp16 textures vs onnxruntime fp32.
    parity_fp16: float = 2e-3
    # Single-op GLSL vs onnxruntime (fp32 arithmetic, different summation order).
    glsl_op_fp32: float = 1e-5
    # onnxruntime vs torch, OpenCV dnn vs onnxruntime (same fp32 math, different kernels).
    onnx_vs_torch: float = 1e-5
    opencv_vs_onnx: float = 1e-4
    # Screen-space baselines (runtime/baselines.py) on an open plane facing the camera (exact AO 1).
    # SSAO: the hemisphere kernel never dips below the plane and the bias is positive -> exactly 1
    # up to float32 rounding of the reprojected depth.
    ssao_open_plane: float = 1e-6
    # GTAO: 4 jittered slices integrate an off-axis pixel's tilted hemisphere only approximately
    # (per-slice error ~ n^2 / 2 for a normal n rad off the view vector; measured max 0.011 at a
    # 40 degree field of view, 0.041 at 60); 0.03 allows the 40-degree test view with margin.
    gtao_open_plane: float = 0.03
    # Minimum drop of mean AO from open floor to floor at a wall's foot (Embree: 0.43). Classic SSAO
    # concentrates its kernel near the pixel and darkens least (measured 0.086; GTAO 0.39).
    screen_space_corner_contrast: float = 0.05
    # Least-squares vs per-vertex baking on a coarse mesh with a contact (tests/test_bake.py): the
    # LSQ surface RMSE must be below this fraction of the vertex-sampling RMSE (L2-optimal
    # piecewise-linear fit vs point samples; measured 0.64 on the 2x2-quad floor with a box, 256 rays).
    bake_lsq_vs_vertex_ratio: float = 0.8


TOL = Tolerances()
