"""The one tolerance table (trimesh's ``tol`` habit). Tests and parity checks read from here.

Every entry says why it has the value it has. Monte-Carlo tolerances are in units of the
estimator's standard error where that is the natural scale.
"""

from __future__ import annotations

import math
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
    # ... for multi-pass image graphs (`neuralao glsl --target image --precision fp16`), relative to
    # max(1, |y|): every intermediate texture rounds to 2^-11 relative and later convs sum those errors
    # with their weights; measured 3.1e-3 on the 5-pass residual test net (tests/test_onnx_glsl.py). An
    # indexing or formula error is O(1).
    parity_fp16_image: float = 1e-2
    # Single-op GLSL vs onnxruntime (fp32 arithmetic, different summation order).
    glsl_op_fp32: float = 1e-5
    # onnxruntime vs torch: the same float32 network in two engines. They differ by rounding only, but
    # each picks its kernels per ISA (AVX2 / AVX-512 / FMA on Intel and AMD) and sums in its own order, so
    # the difference scales with the magnitude of the values and the accumulations behind the output; a
    # fixed absolute figure passes on one CPU and fails on another (1e-5 failed on an AMD EPYC at 1.14e-5,
    # the torchvision-style CNN of tests/test_glsl_external.py, whose outputs reach 18.1). Rule
    # (:meth:`onnx_vs_torch`): atol = onnx_vs_torch_base * max(1, max|ref|) * sqrt(depth), depth = the
    # weighted layers (Conv, ConvTranspose, Gemm, MatMul: neuralao.export.onnx_io.weighted_layers) through
    # which rounding accumulates; base 2^-18 = 64 float32 unit roundoffs (u = 2^-24). Measured, in units of
    # max(1, max|ref|) sqrt(depth) u: that CNN (max|ref| 18.1, 7 convs) 3.0 on an Intel Xeon, 4.0 on the AMD
    # EPYC; its residual U-Net (sigmoid output, 15 convs, larger values inside) 29; the baked MLP <= 5. A
    # wrong weight, index or formula (off by >= 1e-3 of max(1, max|ref|)) is 68x the bound or more up to 15
    # layers (16x at 256).
    onnx_vs_torch_base: float = 2.0**-18
    # OpenCV dnn vs onnxruntime (same fp32 math, different kernels).
    opencv_vs_onnx: float = 1e-4
    # float32 SSIM (torch training loss, pipeline/models/unet_train.py) vs float64 SSIM
    # (runtime/foundation/metrics.py), per pixel or averaged. The variance terms E[x^2] - E[x]^2 cancel
    # catastrophically in float32 (rounding ~6e-8 for values in [0, 1]) and are then divided by
    # (var_x + var_y + C2) >= C2 = 9e-4, so a flat window can be off by ~1e-4; measured 4.2e-5 on
    # constant 0.3 / 0.7 crops and 2e-6 on random images. A wrong window, sigma, padding or mask handling
    # moves SSIM by > 1e-2.
    ssim_fp32_vs_fp64: float = 1e-4
    # Fuzzed GLSL (tests/test_fuzz.py: random image graphs and MLPs, weights up to ~100, inputs up to
    # ~1e3, so sums reach 1e4+ and cancel) vs onnxruntime, both fp32. A fixed absolute or relative
    # tolerance is meaningless under cancellation, so each element is held to this factor times its
    # first-order forward-error bound for |GLSL - onnxruntime| (Higham: an n-term fp32 dot product is
    # within gamma_n = n u / (1 - n u), u = 2^-24, of exact relative to sum |w| |x|, on each side;
    # propagated through later layers with |W| and the activations' slopes; nearest-resize ties and
    # exp rounding as stated in the test). The bound is a worst case, so the factor is 1: measured
    # max |diff| / bound 0.18 over 166 image graphs (seeds 0-199) and 0.09 over 30 MLPs, while an
    # indexing or formula error is off by O(|x|), thousands of times the bound.
    glsl_fuzz_bound: float = 1.0
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
    # Composed scenes (pipeline/geometry/compose.py): gap between an object and what it rests on / touches,
    # relative to the scene diagonal. Contacts come from float32 Embree hit distances in world
    # coordinates <= ~2 (a few ulps, ~1e-6 absolute, ~3e-7 of a ~3-unit diagonal); a composer that
    # only used bounding boxes, or dropped without the reverse rays, leaves gaps of >= 1e-3.
    compose_contact_rel: float = 1e-5
    # ... deepest point of one object inside a closed primitive, relative to the diagonal: edge-edge
    # crossings are caught only at the composer's edge probes (24 per edge), so an edge may sink by
    # up to ~ spacing x slope between probes; an object dropped through another sinks by its size.
    compose_penetration_rel: float = 2e-3
    # Joint bilateral upsampling (runtime/internal_resolution.py): the GLSL pass vs its float64 numpy
    # reference on AO in [0, 1]. Same taps and integer sampling; the weights' exp/pow in float32 differ
    # by a few ulps (measured max 1.3e-5); a wrong tap, flip or weight moves values by > 1e-2.
    upsample_glsl_vs_numpy: float = 1e-4
    # A U-Net's whole frame from its generated compute passes (GTAO, point sampling, the mean-depth
    # reduction, input assembly, the network, upsampling with the hybrid's correction) vs the references
    # (GTAO's GL fragment shaders, numpy, onnxruntime), AO in [0, 1]: the largest of its parts' tolerances
    # (the network's parity_unet_fp32, the upsampling's upsample_glsl_vs_numpy). Measured max 1.0e-6 on
    # llvmpipe and lavapipe (tests/test_frame_passes.py), 7.1e-5 in Chromium's WebGPU on SwiftShader
    # (tests/test_viewer_webgpu.py: GTAO's slice directions are baked constants, so SwiftShader's WGSL
    # cos / sin, off by up to 1.9e-4, move no horizon tap; its other cos / sin / acos stay smooth); a
    # wrong tap, row order or formula is off by > 1e-2.
    frame_passes_vs_reference: float = 1e-4
    # GTAO's pass before its blur computed by another driver's math than the GL reference's: Chromium's
    # WebGPU on SwiftShader, whose WGSL cos / sin / acos are off by up to 1.9e-4 (the slice directions are
    # baked, so no horizon tap moves; the integrand's cos / sin move the value smoothly). Measured max
    # 1.15e-4 (tests/test_viewer_webgpu.py; after the blur, which averages it, 6.8e-5, held to
    # frame_passes_vs_reference); a wrong tap, noise texel or row order is off by > 1e-2.
    gtao_other_driver: float = 2e-4
    # The same view at 256 and at 1024 pixels, the 1024 AO averaged over 4 x 4 foreground blocks, with
    # the network at the internal height 256: mean |difference| over foreground (tests/
    # test_internal_resolution.py). Measured 0.0008-0.019 on test meshes (GTAO itself: 0.003-0.032); a
    # network run at the frame's own resolution differs by 0.036-0.12.
    resolution_independence_mean_abs: float = 0.025
    # Camera poses from a user's file (and instance transforms): max |R^T R - I| and |bottom row - [0 0 0
    # 1]| for a pose to count as rigid. A rotation typed with 5-6 significant digits is off by ~1e-5; a
    # scale of 1.001 (or any shear) by >= 2e-3, which the renderer would draw as a distorted view.
    rigid_pose: float = 1e-4

    def onnx_vs_torch(self, ref_max_abs: float, depth: int) -> float:
        """Allowed max |onnxruntime - torch| for outputs of largest magnitude ``ref_max_abs`` from a
        network of ``depth`` weighted layers (the rule above)."""
        return self.onnx_vs_torch_base * max(1.0, float(ref_max_abs)) * math.sqrt(max(1, int(depth)))


TOL = Tolerances()
