"""Every piece of GLSL text neuralao emits, as named templates, and the one function that fills them.

hls4ml habit: templates here, structure in the writers of ``export/glsl/``, nothing else builds
shader text. Placeholders are ``${name}`` (:class:`string.Template`; ``$`` never occurs in GLSL, so
braces need no escaping). :func:`fill` is strict: a missing or an unexpected field is an error, so a
template and its caller cannot drift apart silently.

Values substituted are generated identifiers (``t3``, ``w0_1``, ``src0``), integers and float
literals produced by the writer; ONNX node and tensor names never reach a template.

Layout conventions the templates rely on (stated again in every manifest):

* fragment MLP: activations are local ``vec4`` arrays, lane ``i % 4`` of element ``i // 4``;
  dense weights are ``vec4`` rows of the (out, in) matrix, input padded to a multiple of 4.
* compute passes: tensors are ``sampler2DArray`` / ``image2DArray`` textures, channel ``c`` in
  layer ``c // 4``, lane ``c % 4``; texel (x, y) holds tensor element [.., y, x] (row 0 = the
  tensor's first row). Parameters are one std430 ``vec4 prm[]`` buffer per pass; a Conv tap is
  a ``mat4`` built from 4 consecutive vec4s, column = input lane, row = output lane.
"""

from __future__ import annotations

from string import Template

_T: dict[str, str] = {}

# --------------------------------------------------------------------------- common

_T["header"] = """#version ${version}
${precision}"""

# ES: float, int and sampler default precisions must be raised (sampler2D defaults to lowp in a
# fragment shader, which would truncate RGBA32F texels).
_T["precision_es"] = """precision highp float;
precision highp int;
precision highp sampler2D;"""

_T["precision_none"] = ""

# Overflow-safe activations: exp() only ever receives a non-positive argument, so no input (not
# even +-1e30) produces inf/inf = NaN, whatever the driver's own tanh/exp do with large values.
_T["prelude"] = """// Overflow-safe activations (exp() only sees arguments <= 0).
vec4 nao_tanh(vec4 x) {
    vec4 e = exp(-2.0 * abs(x));
    return sign(x) * ((1.0 - e) / (1.0 + e));
}

vec4 nao_sigmoid(vec4 x) {
    vec4 e = exp(-abs(x));
    vec4 r = 1.0 / (1.0 + e);
    return mix(e * r, r, greaterThanEqual(x, vec4(0.0)));
}

vec4 nao_leaky_relu(vec4 x, float alpha) {
    return mix(alpha * x, x, greaterThanEqual(x, vec4(0.0)));
}"""

# Activation expressions by ONNX op type; ``x`` is any vec4 expression.
_T["act_Relu"] = "max(${x}, vec4(0.0))"
_T["act_LeakyRelu"] = "nao_leaky_relu(${x}, ${alpha})"
_T["act_Sigmoid"] = "nao_sigmoid(${x})"
_T["act_Tanh"] = "nao_tanh(${x})"
# min(max()) rather than clamp(): GLSL leaves clamp undefined for lo > hi; ONNX Clip then gives hi.
_T["act_Clip"] = "min(max(${x}, vec4(${lo})), vec4(${hi}))"
_T["act_Clip_min"] = "max(${x}, vec4(${lo}))"
_T["act_Clip_max"] = "min(${x}, vec4(${hi}))"
_T["act_Identity"] = "${x}"
# Sin / Cos: the builtins (Mesa: Cephes-style range reduction, ~1e-7 absolute for |x| <~ 1e3; the
# field encoding keeps |x| <= 2^(octaves-1) pi and its arguments bit-identical to onnxruntime's).
_T["act_Sin"] = "sin(${x})"
_T["act_Cos"] = "cos(${x})"
# Elu: exp() of min(x, 0) only; Softplus as max(x, 0) + log(1 + exp(-|x|)), so exp() never overflows.
_T["act_Elu"] = "mix(${alpha} * (exp(min(${x}, vec4(0.0))) - 1.0), ${x}, greaterThanEqual(${x}, vec4(0.0)))"
_T["act_Softplus"] = "(max(${x}, vec4(0.0)) + log(1.0 + exp(-abs(${x}))))"
_T["act_HardSigmoid"] = "clamp(${alpha} * ${x} + ${beta}, 0.0, 1.0)"
# HardSwish (opset 14; torch nn.Hardswish): x * HardSigmoid(x) with alpha 1/6, beta 1/2 (the spec's).
_T["act_HardSwish"] = "(${x} * clamp(0.16666667 * ${x} + 0.5, 0.0, 1.0))"

# Erf (NR's erfc, fractional error < 1.2e-7, for |x| >= 0.5; the Maclaurin series below, where 1 - erfc
# would lose the relative accuracy of small values); Gelu's two forms and Mish after ONNX's definitions.
_T["prelude_erf"] = """vec4 nao_erf(vec4 x) {
    vec4 z = abs(x);
    vec4 t = 1.0 / (1.0 + 0.5 * z);
    vec4 p = -z * z - 1.26551223 + t * (1.00002368 + t * (0.37409196 + t * (0.09678418 + t * (-0.18628806
        + t * (0.27886807 + t * (-1.13520398 + t * (1.48851587 + t * (-0.82215223 + t * 0.17087277))))))));
    vec4 big = sign(x) * (1.0 - t * exp(p));
    vec4 x2 = x * x;
    vec4 small = 1.1283791671 * x * (1.0 + x2 * (-0.3333333333 + x2 * (0.1 + x2 * (-0.0238095238
        + x2 * (0.0046296296 + x2 * -0.0007575758)))));
    return mix(big, small, lessThan(z, vec4(0.5)));
}"""
_T["act_Erf"] = "nao_erf(${x})"
_T["act_Gelu"] = "(0.5 * ${x} * (1.0 + nao_erf(${x} * 0.70710678118654752)))"
_T["act_GeluTanh"] = "(0.5 * ${x} * (1.0 + nao_tanh(0.79788456080286536 * (${x} + 0.044715 * ${x} * ${x} * ${x}))))"
_T["act_Mish"] = "(${x} * nao_tanh(max(${x}, vec4(0.0)) + log(1.0 + exp(-abs(${x})))))"
_T["act_Sqrt"] = "sqrt(${x})"
_T["act_Exp"] = "exp(${x})"
_T["act_Log"] = "log(${x})"
_T["act_Abs"] = "abs(${x})"
_T["act_Neg"] = "(-${x})"
_T["act_Reciprocal"] = "(1.0 / ${x})"
_T["act_Sign"] = "sign(${x})"
_T["act_Softsign"] = "(${x} / (1.0 + abs(${x})))"
_T["act_Floor"] = "floor(${x})"
_T["act_Ceil"] = "ceil(${x})"
_T["act_Pow"] = "pow(${x}, vec4(${e}))"
_T["act_Pow_one"] = "vec4(1.0)"
_T["act_Pow_reciprocal"] = "(1.0 / ${x})"
_T["pow_product"] = "(${factors})"

# --------------------------------------------------------------------------- fragment MLP

_T["fullscreen_vertex"] = """${header}
// neuralao: full-screen triangle from gl_VertexID; draw 3 vertices with an empty VAO.
void main() {
    vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""

_T["sampler2d_decl"] = "uniform sampler2D ${name};"
_T["sampler2d_decl_binding"] = "layout(binding = ${binding}) uniform sampler2D ${name};"

_T["ubo_block"] = """${layout}uniform ${block} {
${members}
};"""
_T["ubo_layout"] = "layout(std140) "
_T["ubo_layout_binding"] = "layout(std140, binding = ${binding}) "
_T["ubo_member"] = "    ${type} ${name}[${count}];"

_T["vector_fragment"] = """${header}
// ${description}
// Generated from the ONNX graph; ${weights}

${prelude}

${samplers}

// Dense layers are mat4 x vec4 products of 4x4 weight tiles: small layers straight-line (constant
// indices, registers), large ones a loop over output vec4s. u_loop_guard is always 0 (never set it):
// loop bounds read it so llvmpipe cannot unroll them (LLVM then spent 26-100 s on one shader).
uniform int u_loop_guard;

${blocks}

layout(location = 0) out vec4 o_result;

void main() {
    vec4 g0 = texelFetch(${mask_sampler}, ivec2(gl_FragCoord.xy), 0);
    if (g0.w < 0.5) {
        o_result = vec4(1.0);  // background: ao = 1
        return;
    }
${fetches}
${body}
    o_result = ${result};
}
"""

_T["weights_uniform"] = "weights in ${n_blocks} std140 uniform block(s), each <= ${max_block_bytes} bytes."
_T["weights_constant"] = "weights as const arrays in this source (nothing to bind)."
_T["const_array"] = "const ${type} ${name}[${count}] = ${type}[${count}](${items});"
_T["const_item"] = "${type}(${values})"

_T["texel_fetch"] = "    vec4 g${index} = texelFetch(${sampler}, ivec2(gl_FragCoord.xy), 0);"

_T["vec_decl"] = "    vec4 ${name}[${count}];"
_T["input_tile"] = "    ${dst}[${index}] = vec4(${c0}, ${c1}, ${c2}, ${c3});"

# Dense layers, straight-line: output vec4 j = act(bias[j] + sum_i tile[j, i] * src[i]) (mat4 tiles).
_T["mat_term"] = "${weight}[${index}] * ${src}[${i}]"
_T["dense_acc"] = "(${bias}[${j}] + ${terms})"
_T["dense_row"] = "    ${dst}[${j}] = ${value};"
# A large layer: the rows of a chunk in a loop whose bound reads u_loop_guard (always 0: uniforms start
# at 0; never set it), so the compiler cannot see a constant trip count and unroll it.
_T["dense_loop"] = """    for (int j = ${j_begin}; j < ${j_end} + u_loop_guard; ++j) {
    ${row}
    }"""

_T["vec_map"] = "    ${dst}[${j}] = ${expr};"

_T["index_j"] = "${name}[${j}]"
_T["binop"] = "(${a} ${op} ${b})"
_T["vec_copy"] = "    ${dst}[${di}] = ${src}[${si}];"
_T["lane_copy"] = "    ${dst}[${di}].${dl} = ${src}[${si}].${sl};"
_T["lane_zero"] = "    ${dst}[${di}].${dl} = 0.0;"
_T["index_0"] = "${name}[0]"

# --------------------------------------------------------------------------- compute passes

_T["compute_pass"] = """${header}
// neuralao compute pass ${pass_index}: ${summary}
layout(local_size_x = ${local_x}, local_size_y = ${local_y}, local_size_z = 1) in;

${prelude}

${declarations}

void main() {
    ivec3 gid = ivec3(gl_GlobalInvocationID);
    ivec2 out_size = imageSize(dst).xy;
    if (gid.x >= out_size.x || gid.y >= out_size.y || gid.z >= ${out_layers}) {
        return;
    }
${body}
${epilogue}
    imageStore(dst, gid, r);
}
"""

_T["sampler_array_decl"] = "layout(binding = ${binding}) uniform highp sampler2DArray ${name};"
_T["image_array_decl"] = "layout(binding = ${binding}, ${format}) writeonly uniform highp image2DArray dst;"
_T["params_decl"] = """layout(std430, binding = ${binding}) readonly buffer Params {
    vec4 prm[];
};"""
_T["uniform_int_decl"] = "layout(location = ${location}) uniform int ${name};"
_T["uniform_float_decl"] = "layout(location = ${location}) uniform float ${name};"
_T["size_decl"] = "    ivec2 ${size} = textureSize(${src}, 0).xy;"

# Conv: one invocation = one output texel (4 output channels of layer gid.z).
_T["conv_body"] = """${sizes}
    vec4 r = prm[${bias_offset} + gid.z];
    for (int ky = 0; ky < ${kh}; ++ky) {
        int iy = gid.y * ${sy} - ${pad_top} + ky * ${dy};
        for (int kx = 0; kx < ${kw}; ++kx) {
            int ix = gid.x * ${sx} - ${pad_left} + kx * ${dx};
            int tap = ${weight_offset} + ((gid.z * ${kh} + ky) * ${kw} + kx) * ${tap_stride};
${input_loops}
        }
    }"""

# Zero padding: taps outside the input contribute nothing (texelFetch outside is undefined).
_T["conv_input_loop"] = """            if (iy >= 0 && iy < ${size}.y && ix >= 0 && ix < ${size}.x) {
                for (int l = 0; l < ${layers}; ++l) {
                    vec4 v = texelFetch(${src}, ivec3(ix, iy, l), 0);
                    int o = tap + (${layer_offset} + l) * 4;
                    r += mat4(prm[o], prm[o + 1], prm[o + 2], prm[o + 3]) * v;
                }
            }"""

# Conv, blocked: one invocation = a ${block_x} x ${block_y} block of output texels x ${block_layers}
# output layers (z0 = block_layers * gid.z ..). Each input texel fetched feeds every output layer of
# the block and each mat4 of weights every texel of it; accumulators a<o>_<p> are straight-line
# registers (layer o, texel p), the tap and input-layer loops stay loops. Helper functions keep the
# source short (the compiler inlines them).
_T["compute_pass_block"] = """${header}
// neuralao compute pass ${pass_index}: ${summary}
// One invocation: ${block_x}x${block_y} output texels x ${block_layers} output layer(s) from layer ${block_layers} * gid.z.
layout(local_size_x = ${local_x}, local_size_y = ${local_y}, local_size_z = 1) in;

${prelude}

${declarations}

// Zero padding without a branch: q is clamped into the input; returns 1 inside, 0 outside (texels
// are finite, so 0 * texel is 0).
float nao_clip(inout ivec2 q, ivec2 size) {
    float k = all(greaterThanEqual(q, ivec2(0))) && all(lessThan(q, size)) ? 1.0 : 0.0;
    q = clamp(q, ivec2(0), size - 1);
    return k;
}

mat4 nao_tap(int o) {
    return mat4(prm[o], prm[o + 1], prm[o + 2], prm[o + 3]);
}

// Epilogue and store of output texel xy, layer z (skipped outside the output: partial blocks).
void nao_store(ivec2 xy, int z, vec4 r) {
    if (all(lessThan(xy, imageSize(dst).xy))) {
${epilogue}
        imageStore(dst, ivec3(xy, z), r);
    }
}

void main() {
    ivec3 gid = ivec3(gl_GlobalInvocationID);
    ivec2 base = gid.xy * ivec2(${block_x}, ${block_y});
    int z0 = gid.z * ${block_layers};
    if (any(greaterThanEqual(base, imageSize(dst).xy))) {
        return;
    }
${body}
${stores}
}
"""

_T["conv_block_body"] = """    ivec2 in_size = textureSize(src0, 0).xy;
${acc_init}
    for (int ky = 0; ky < ${kh}; ++ky) {
        for (int kx = 0; kx < ${kw}; ++kx) {
            int tap = ${weight_offset} + ((z0 * ${kh} + ky) * ${kw} + kx) * ${tap_stride};
            ivec2 qb = base * ivec2(${sx}, ${sy}) + ivec2(kx * ${dx} - ${pad_left}, ky * ${dy} - ${pad_top});
${coords}
${input_loops}
        }
    }"""
_T["conv_block_bias"] = "    vec4 b${o} = prm[${bias_offset} + z0 + ${o}];"
_T["conv_block_acc"] = "    vec4 ${names};"
_T["conv_block_acc_name"] = "a${o}_${p} = b${o}"
_T["conv_block_coord"] = "            ivec2 q${p} = qb + ivec2(${qx}, ${qy}); float k${p} = nao_clip(q${p}, in_size);"
_T["conv_block_input_loop"] = """            for (int l = 0; l < ${layers}; ++l) {
                int o = tap + (${layer_offset} + l) * 4;
${fetches}
${products}
            }"""
_T["conv_block_fetch"] = "                vec4 v${p} = texelFetch(${src}, ivec3(q${p}, l), 0) * k${p};"
_T["conv_block_weight"] = "                mat4 m${o} = nao_tap(o + ${off});"
_T["conv_block_fma"] = "a${o}_${p} += m${o} * v${p};"
_T["conv_block_fmas"] = "                ${fmas}"
_T["conv_block_store"] = "    nao_store(base + ivec2(${px}, ${py}), z0 + ${o}, a${o}_${p});"

# ConvTranspose as a gather: output y takes input iy where y = iy * stride - pad + ky * dilation.
_T["conv_transpose_body"] = """${sizes}
    vec4 r = prm[${bias_offset} + gid.z];
    for (int ky = 0; ky < ${kh}; ++ky) {
        int ty = gid.y + ${pad_top} - ky * ${dy};
        if (ty < 0 || ty % ${sy} != 0) {
            continue;
        }
        int iy = ty / ${sy};
        for (int kx = 0; kx < ${kw}; ++kx) {
            int tx = gid.x + ${pad_left} - kx * ${dx};
            if (tx < 0 || tx % ${sx} != 0) {
                continue;
            }
            int ix = tx / ${sx};
            int tap = ${weight_offset} + ((gid.z * ${kh} + ky) * ${kw} + kx) * ${tap_stride};
${input_loops}
        }
    }"""

# Depthwise conv (group = channels): output layer gid.z reads input layer gid.z only, one vec4 per tap.
_T["conv_depthwise_body"] = """    ivec2 in_size = textureSize(src0, 0).xy;
    vec4 r = prm[${bias_offset} + gid.z];
    for (int ky = 0; ky < ${kh}; ++ky) {
        int iy = gid.y * ${sy} - ${pad_top} + ky * ${dy};
        if (iy < 0 || iy >= in_size.y) {
            continue;
        }
        for (int kx = 0; kx < ${kw}; ++kx) {
            int ix = gid.x * ${sx} - ${pad_left} + kx * ${dx};
            if (ix < 0 || ix >= in_size.x) {
                continue;
            }
            r += prm[${weight_offset} + (gid.z * ${kh} + ky) * ${kw} + kx] * texelFetch(src0, ivec3(ix, iy, gid.z), 0);
        }
    }"""

# count: taps inside the input; count_padded: taps inside the padded input (ceil_mode windows may
# reach past the trailing pads; count_include_pad divides by count_padded, as onnxruntime does).
_T["pool_body"] = """    ivec2 in_size = textureSize(src0, 0).xy;
    vec4 r = ${init};
    int count = 0;
    int count_padded = 0;
    for (int ky = 0; ky < ${kh}; ++ky) {
        int iy = gid.y * ${sy} - ${pad_top} + ky * ${dy};
        if (iy < -${pad_top} || iy >= in_size.y + ${pad_bottom}) {
            continue;
        }
        for (int kx = 0; kx < ${kw}; ++kx) {
            int ix = gid.x * ${sx} - ${pad_left} + kx * ${dx};
            if (ix < -${pad_left} || ix >= in_size.x + ${pad_right}) {
                continue;
            }
            count_padded += 1;
            if (iy < 0 || iy >= in_size.y || ix < 0 || ix >= in_size.x) {
                continue;
            }
            vec4 v = texelFetch(src0, ivec3(ix, iy, gid.z), 0);
            r = ${accumulate};
            count += 1;
        }
    }
${finish}"""
_T["pool_init_avg"] = "vec4(0.0)"
_T["pool_init_max"] = "vec4(-3.402823466e+38)"
_T["pool_acc_avg"] = "r + v"
_T["pool_acc_max"] = "max(r, v)"
_T["pool_finish_count"] = "    r /= float(max(count, 1));"
_T["pool_finish_padded"] = "    r /= float(max(count_padded, 1));"
_T["pool_finish_none"] = "    // max pool: no normalisation"
# Lp pools: the sum of |x|^p over the window (padding adds nothing), then its p-th root.
_T["pool_init_lp"] = "vec4(0.0)"
_T["pool_acc_l1"] = "r + abs(v)"
_T["pool_acc_l2"] = "r + v * v"
_T["pool_acc_lp"] = "r + pow(abs(v), vec4(${p}))"
_T["pool_finish_l1"] = "    // L1: the sum itself"
_T["pool_finish_l2"] = "    r = sqrt(r);"
_T["pool_finish_lp"] = "    r = pow(r, vec4(${inv_p}));"

# Global pools: one invocation per output layer walks the whole input (the output is 1 x 1).
_T["global_pool_body"] = """    ivec2 in_size = textureSize(src0, 0).xy;
    vec4 r = ${init};
    for (int iy = 0; iy < in_size.y; ++iy) {
        for (int ix = 0; ix < in_size.x; ++ix) {
            vec4 v = texelFetch(src0, ivec3(ix, iy, gid.z), 0);
            r = ${accumulate};
        }
    }
${finish}"""
_T["global_finish_mean"] = "    r /= float(in_size.x * in_size.y);"

# Resize: source coordinate per ONNX coordinate_transformation_mode (x: output index as float), the
# float32 operations of the ONNX formulas in onnxruntime's order, each correctly rounded: a coordinate
# that is exactly an integer or a half (scale 1.5, 0.75, ...) must not come out one ulp off, or
# nearest mode's floor / ceil / tie rounding picks the neighbouring pixel. GLSL allows 2.5 ulp for
# ``/`` (llvmpipe computes a * rcp(b)) and may contract a * b + c into an fma, hence nao_div and the
# ``precise`` coordinates in the resize bodies (found by tests/test_fuzz.py, seed 33).
# nao_div: correctly rounded a / b (one exact fma residual step on the <= 2.5 ulp GLSL quotient).
_T["prelude_div"] = """float nao_div(float a, float b) {
    precise float q = a / b;
    precise float r = fma(-q, b, a);
    precise float d = q + r / b;
    return d;
}"""
_T["coord_half_pixel"] = "(nao_div(${x} + 0.5, ${scale}) - 0.5)"
_T["coord_pytorch_half_pixel"] = "(${len_out} > 1.0 ? nao_div(${x} + 0.5, ${scale}) - 0.5 : 0.0)"
_T["coord_align_corners"] = "(${len_out} > 1.0 ? nao_div(${x} * (${len_in} - 1.0), ${len_out} - 1.0) : 0.0)"
_T["coord_asymmetric"] = "nao_div(${x}, ${scale})"
_T["coord_half_pixel_symmetric"] = (
    "(${len_in} * 0.5 * (1.0 - nao_div(${len_out}, ${scale} * ${len_in})) + nao_div(${x} + 0.5, ${scale}) - 0.5)"
)
# tf_crop_and_resize: roi start / end literals of this axis, in onnxruntime's operation order.
_T["coord_tf_crop_and_resize"] = (
    "(${len_out} > 1.0 ? ${start} * (${len_in} - 1.0) + nao_div(${x} * (${end} - ${start}) * (${len_in} - 1.0), "
    "${len_out} - 1.0) : 0.5 * (${start} + ${end}) * (${len_in} - 1.0))"
)
_T["scale_literal"] = "${value}"
_T["scale_ratio"] = "nao_div(${len_out}, ${len_in})"
_T["float_of"] = "float(${v})"

# Nearest index per nearest_mode, exact for non-negative coordinates (negative ones clamp to 0).
_T["round_round_prefer_floor"] = "(fract(${v}) > 0.5 ? ceil(${v}) : floor(${v}))"
_T["round_round_prefer_ceil"] = "(fract(${v}) >= 0.5 ? ceil(${v}) : floor(${v}))"
_T["round_floor"] = "floor(${v})"
_T["round_ceil"] = "ceil(${v})"

_T["resize_linear_body"] = """    ivec2 in_size = textureSize(src0, 0).xy;
    precise float fy = ${coord_y};
    precise float fx = ${coord_x};
${outside}
    fy = clamp(fy, 0.0, float(in_size.y - 1));
    fx = clamp(fx, 0.0, float(in_size.x - 1));
    int y0 = int(fy);
    int x0 = int(fx);
    int y1 = min(y0 + 1, in_size.y - 1);
    int x1 = min(x0 + 1, in_size.x - 1);
    float wy = fy - float(y0);
    float wx = fx - float(x0);
    vec4 a = texelFetch(src0, ivec3(x0, y0, gid.z), 0);
    vec4 b = texelFetch(src0, ivec3(x1, y0, gid.z), 0);
    vec4 c = texelFetch(src0, ivec3(x0, y1, gid.z), 0);
    vec4 d = texelFetch(src0, ivec3(x1, y1, gid.z), 0);
    vec4 r = (a * (1.0 - wx) + b * wx) * (1.0 - wy) + (c * (1.0 - wx) + d * wx) * wy;
    if (outside) {
        r = vec4(${extrapolation});
    }"""

_T["resize_nearest_body"] = """    ivec2 in_size = textureSize(src0, 0).xy;
    precise float fy = ${coord_y};
    precise float fx = ${coord_x};
${outside}
    int iy = clamp(int(${round_y}), 0, in_size.y - 1);
    int ix = clamp(int(${round_x}), 0, in_size.x - 1);
    vec4 r = texelFetch(src0, ivec3(ix, iy, gid.z), 0);
    if (outside) {
        r = vec4(${extrapolation});
    }"""

# tf_crop_and_resize: a source coordinate outside the input gives extrapolation_value.
_T["resize_outside"] = (
    "    bool outside = fy < 0.0 || fy > float(in_size.y - 1) || fx < 0.0 || fx > float(in_size.x - 1);"
)
_T["resize_inside"] = "    const bool outside = false;"

# Separable filter (cubic, or linear / cubic widened by 1 / scale when antialiasing a downscale):
# taps floor(f) - half + 1 .. floor(f) + half per axis, weights normalised by their sum (onnxruntime).
_T["resize_filter_body"] = """    ivec2 in_size = textureSize(src0, 0).xy;
    precise float fy = ${coord_y};
    precise float fx = ${coord_x};
${outside}
    int y_first = int(floor(fy)) - ${half_y} + 1;
    int x_first = int(floor(fx)) - ${half_x} + 1;
    vec4 acc = vec4(0.0);
    float wsum = 0.0;
    for (int j = 0; j < ${taps_y}; ++j) {
        int iy = y_first + j;
        float wy = ${weight_y};
${exclude_y}
        iy = clamp(iy, 0, in_size.y - 1);
        for (int i = 0; i < ${taps_x}; ++i) {
            int ix = x_first + i;
            float wx = ${weight_x};
${exclude_x}
            ix = clamp(ix, 0, in_size.x - 1);
            acc += (wy * wx) * texelFetch(src0, ivec3(ix, iy, gid.z), 0);
            wsum += wy * wx;
        }
    }
    vec4 r = acc / wsum;
    if (outside) {
        r = vec4(${extrapolation});
    }"""
_T["filter_arg"] = "((float(${i}) - ${f}) * ${widen})"
_T["kernel_linear"] = "max(0.0, 1.0 - abs(${t}))"
_T["kernel_cubic"] = "nao_cubic(${t}, ${a})"
_T["filter_exclude_y"] = """        if (iy < 0 || iy >= in_size.y) {
            wy = 0.0;  // exclude_outside
        }"""
_T["filter_exclude_x"] = """            if (ix < 0 || ix >= in_size.x) {
                wx = 0.0;  // exclude_outside
            }"""
_T["filter_edge_y"] = "        // taps outside the input read the edge texel"
_T["filter_edge_x"] = "            // taps outside the input read the edge texel"
# Keys cubic convolution kernel with coefficient a (ONNX cubic_coeff_a), support |t| < 2.
_T["prelude_cubic"] = """float nao_cubic(float t, float a) {
    float x = abs(t);
    if (x <= 1.0) {
        return ((a + 2.0) * x - (a + 3.0)) * x * x + 1.0;
    }
    if (x < 2.0) {
        return ((x - 5.0) * x + 8.0) * x * a - 4.0 * a;
    }
    return 0.0;
}"""

_T["concat_body"] = """    vec4 r = vec4(0.0);
    for (int lane = 0; lane < 4; ++lane) {
        int c = gid.z * 4 + lane;
${branches}
    }"""
_T["concat_branch"] = """        if (c >= ${begin} && c < ${end}) {
            r[lane] = texelFetch(${src}, ivec3(gid.xy, (c - ${begin}) / 4), 0)[(c - ${begin}) % 4];
        }"""

# A scalar graph input (a uniform) as a 1x1 one-channel texture; the padding lanes hold 0.
_T["uniform_body"] = "    vec4 r = vec4(${name}, 0.0, 0.0, 0.0);"

_T["elementwise_body"] = "    vec4 r = texelFetch(src0, gid, 0);"

# Two images a (src0) and b (src1); a 1x1 or one-channel operand is broadcast.
_T["binary_body"] = """    vec4 a = ${fetch_a};
    vec4 b = ${fetch_b};
${guard}
    vec4 r = ${expr};"""
_T["fetch_full"] = "texelFetch(${src}, gid, 0)"
_T["fetch_pixel"] = "texelFetch(${src}, ivec3(0, 0, gid.z), 0)"
_T["fetch_channel"] = "texelFetch(${src}, ivec3(gid.xy, 0), 0).xxxx"
_T["fetch_scalar"] = "texelFetch(${src}, ivec3(0), 0).xxxx"
# Padding lanes divide by 1, so they stay finite (a later conv multiplies them by zero weights).
_T["binary_guard_div"] = (
    "    b = mix(vec4(1.0), b, lessThan(ivec4(4 * gid.z) + ivec4(0, 1, 2, 3), ivec4(${channels})));"
)
_T["binary_guard_none"] = "    // no guard"
_T["binop_Add"] = "a + b"
_T["binop_Sub"] = "a - b"
_T["binop_Mul"] = "a * b"
_T["binop_Div"] = "a / b"
_T["binop_Max"] = "max(a, b)"
_T["binop_Min"] = "min(a, b)"

# ONNX Pad on H, W (negative pads crop): output texel (x, y) reads input (x - left, y - top).
_T["spatial_pad_body"] = """    ivec2 in_size = textureSize(src0, 0).xy;
    int x = gid.x - ${left};
    int y = gid.y - ${top};
${mode}"""
_T["pad_constant"] = """    vec4 r = vec4(${value});
    if (x >= 0 && x < in_size.x && y >= 0 && y < in_size.y) {
        r = texelFetch(src0, ivec3(x, y, gid.z), 0);
    }"""
_T["pad_edge"] = (
    "    vec4 r = texelFetch(src0, ivec3(clamp(x, 0, in_size.x - 1), clamp(y, 0, in_size.y - 1), gid.z), 0);"
)
# Reflect (edge sample not repeated) for any pad width: fold |x| into one period 2 (n - 1).
_T["pad_reflect"] = """    ivec2 period = max(2 * (in_size - 1), ivec2(1));
    ivec2 m = abs(ivec2(x, y)) % period;
    vec4 r = texelFetch(src0, ivec3(min(m, period - m), gid.z), 0);"""
# Wrap: GLSL leaves % of negative operands undefined, so negative indices count from the end.
_T["pad_wrap"] = """    x = x >= 0 ? x % in_size.x : in_size.x - 1 - (-x - 1) % in_size.x;
    y = y >= 0 ? y % in_size.y : in_size.y - 1 - (-y - 1) % in_size.y;
    vec4 r = texelFetch(src0, ivec3(x, y, gid.z), 0);"""

# Reflect padding at the bottom/right (numpy/torch "reflect": the edge sample is not repeated).
_T["pad_reflect_body"] = """    ivec2 in_size = textureSize(src0, 0).xy;
    int x = gid.x < in_size.x ? gid.x : 2 * (in_size.x - 1) - gid.x;
    int y = gid.y < in_size.y ? gid.y : 2 * (in_size.y - 1) - gid.y;
    x = clamp(x, 0, in_size.x - 1);
    y = clamp(y, 0, in_size.y - 1);
    if (u_flip_y != 0) {
        y = in_size.y - 1 - y;  // source texture stored bottom-up (a GL render target)
    }
    vec4 r = texelFetch(src0, ivec3(x, y, gid.z), 0);"""

_T["crop_body"] = """    int y = u_flip_y != 0 ? out_size.y - 1 - gid.y : gid.y;
    vec4 r = texelFetch(src0, ivec3(gid.x, y, gid.z), 0);"""

_T["epilogue_act"] = "    r = ${expr};"
# ${z}: the output layer (gid.z, or at.z in a blocked conv's stores).
_T["epilogue_affine"] = "    r = r * prm[${scale_offset} + ${z}] + prm[${shift_offset} + ${z}];"
_T["epilogue_prelu"] = "    r = mix(r * prm[${slope_offset} + ${z}], r, greaterThanEqual(r, vec4(0.0)));"
# constant / x; padding lanes divide by 1 (they stay finite).
_T["epilogue_rdiv"] = (
    "    r = prm[${offset} + ${z}] / mix(vec4(1.0), r, lessThan(ivec4(4 * ${z}) + ivec4(0, 1, 2, 3), "
    "ivec4(${channels})));"
)
_T["epilogue_none"] = "    // no epilogue"
# Padding lanes (channels >= ${channels}) to 0 after an activation that could make them inf or NaN.
_T["epilogue_guard"] = (
    "    r = mix(vec4(0.0), r, lessThan(ivec4(4 * ${z}) + ivec4(0, 1, 2, 3), ivec4(${channels})));"
)

# Gather (a view materialised: DepthToSpace, SpaceToDepth, channel shuffles, transposes): each output
# coordinate is split into its digits, innermost first; each digit moves one source coordinate (s.z:
# the channel) by its stride. The outermost digit of an axis takes the rest of the index (no modulo).
_T["gather_body"] = """    vec4 r = vec4(0.0);
    for (int lane = 0; lane < 4; ++lane) {
        int c = gid.z * 4 + lane;
        if (c >= ${channels}) {
            break;
        }
        ivec3 s = ivec3(0);  // source x, y, channel
        int v = c;
${digits_c}
        v = gid.y;
${digits_y}
        v = gid.x;
${digits_x}
        r[lane] = texelFetch(src0, ivec3(s.xy, s.z / 4), 0)[s.z % 4];
    }"""
_T["gather_digit"] = """        s.${coord} += (v % ${size}) * ${stride};
        v /= ${size};"""
_T["gather_digit_last"] = "        s.${coord} += v * ${stride};"

# Member loops of a reduction (reduce, moments): the pixels of the output texel's window (the whole
# image on a reduced axis) x the members of channel group g (prm tables: base per group, offsets).
_T["member_loops"] = """        for (int iy = ${y_begin}; iy < ${y_end}; ++iy) {
            for (int ix = ${x_begin}; ix < ${x_end}; ++ix) {
                for (int k = 0; k < ${members}; ++k) {
                    int c = base + int(prm[${offsets_offset} + k / 4][k % 4]);
                    float v = texelFetch(src0, ivec3(ix, iy, c / 4), 0)[c % 4];
                    ${statement}
                }
            }
        }"""
_T["reduce_body"] = """    ivec2 in_size = textureSize(src0, 0).xy;
    vec4 r = vec4(0.0);
    for (int lane = 0; lane < 4; ++lane) {
        int g = gid.z * 4 + lane;
        if (g >= ${groups}) {
            break;
        }
        int base = int(prm[${base_offset} + g / 4][g % 4]);
        float n = float(${members} * (${y_end} - ${y_begin}) * (${x_end} - ${x_begin}));
        float s = ${init};
${loops}
        r[lane] = ${finish};
    }"""
_T["reduce_init_zero"] = "0.0"
_T["reduce_init_one"] = "1.0"
_T["reduce_init_max"] = "-3.402823466e+38"
_T["reduce_init_min"] = "3.402823466e+38"
_T["reduce_acc_sum"] = "s += v;"
_T["reduce_acc_square"] = "s += v * v;"
_T["reduce_acc_abs"] = "s += abs(v);"
_T["reduce_acc_max"] = "s = max(s, v);"
_T["reduce_acc_min"] = "s = min(s, v);"
_T["reduce_acc_prod"] = "s *= v;"
_T["reduce_finish_none"] = "s"
_T["reduce_finish_mean"] = "s / n"
_T["reduce_finish_sqrt"] = "sqrt(s)"
_T["reduce_finish_log"] = "log(s)"

# Moments: channel j < groups holds the mean of group j, channel groups + j its 1 / sqrt(var + epsilon)
# (two passes over the members: the mean, then the squared deviations from it, as onnxruntime does).
_T["moments_body"] = """    ivec2 in_size = textureSize(src0, 0).xy;
    vec4 r = vec4(0.0);
    for (int lane = 0; lane < 4; ++lane) {
        int j = gid.z * 4 + lane;
        if (j >= ${channels}) {
            break;
        }
        int g = j % ${groups};
        int base = int(prm[${base_offset} + g / 4][g % 4]);
        float n = float(${members} * (${y_end} - ${y_begin}) * (${x_end} - ${x_begin}));
        float s = 0.0;
${sum_loops}
        float mean = s / n;
        if (j < ${groups}) {
            r[lane] = mean;
            continue;
        }
        s = 0.0;
${square_loops}
        r[lane] = 1.0 / sqrt(s / n + ${epsilon});
    }"""
_T["moments_acc_square"] = "s += (v - mean) * (v - mean);"

# Normalize: src0 the image, src1 its moments (mean at channel g, 1/std at groups + g); the group of
# each channel in prm (padding lanes: group 0, so they stay finite).
_T["normalize_body"] = """    vec4 x = texelFetch(src0, gid, 0);
    vec4 r = vec4(0.0);
    for (int lane = 0; lane < 4; ++lane) {
        int g = int(prm[${group_offset} + gid.z][lane]);
        int h = g + ${groups};
        float mean = texelFetch(src1, ivec3(${stats_x}, ${stats_y}, g / 4), 0)[g % 4];
        float rstd = texelFetch(src1, ivec3(${stats_x}, ${stats_y}, h / 4), 0)[h % 4];
        r[lane] = (x[lane] - mean) * rstd;
    }"""

# Softmax over the channels of a group at one pixel (prm: the group's first channel per channel, offsets).
_T["softmax_body"] = """    vec4 x = texelFetch(src0, gid, 0);
    vec4 r = vec4(0.0);
    for (int lane = 0; lane < 4; ++lane) {
        int c = gid.z * 4 + lane;
        if (c >= ${channels}) {
            break;
        }
        int base = int(prm[${base_offset} + gid.z][lane]);
        float m = -3.402823466e+38;
        for (int k = 0; k < ${members}; ++k) {
            int q = base + int(prm[${offsets_offset} + k / 4][k % 4]);
            m = max(m, texelFetch(src0, ivec3(gid.xy, q / 4), 0)[q % 4]);
        }
        float s = 0.0;
        for (int k = 0; k < ${members}; ++k) {
            int q = base + int(prm[${offsets_offset} + k / 4][k % 4]);
            s += exp(texelFetch(src0, ivec3(gid.xy, q / 4), 0)[q % 4] - m);
        }
        r[lane] = ${finish};
    }"""
_T["softmax_finish"] = "exp(x[lane] - m) / s"
_T["log_softmax_finish"] = "x[lane] - m - log(s)"

# LRN across channels: x / (bias + alpha / size * sum of squares over the window) ^ beta.
_T["lrn_body"] = """    vec4 x = texelFetch(src0, gid, 0);
    vec4 r = vec4(0.0);
    for (int lane = 0; lane < 4; ++lane) {
        int c = gid.z * 4 + lane;
        if (c >= ${channels}) {
            break;
        }
        float s = 0.0;
        for (int k = max(c - ${before}, 0); k <= min(c + ${after}, ${channels} - 1); ++k) {
            float v = texelFetch(src0, ivec3(gid.xy, k / 4), 0)[k % 4];
            s += v * v;
        }
        r[lane] = x[lane] / pow(${bias} + ${alpha} * s, ${beta});
    }"""

# --------------------------------------------------------------------------- baseline: vertex-colour AO

# The cheapest AO an engine can draw (baked per-vertex values, Sloan et al. style), used by the
# benchmark as the reference cost next to the MLP pass.
_T["vertex_colour_vert"] = """${header}
layout(location = 0) in vec3 a_position;
layout(location = 1) in float a_ao;
uniform mat4 u_mvp;
out float v_ao;
void main() {
    v_ao = a_ao;
    gl_Position = u_mvp * vec4(a_position, 1.0);
}
"""

_T["vertex_colour_frag"] = """${header}
in float v_ao;
layout(location = 0) out vec4 o_colour;
void main() {
    o_colour = vec4(vec3(v_ao), 1.0);
}
"""

TEMPLATES: dict[str, Template] = {name: Template(text) for name, text in _T.items()}


def fill_from(templates: dict[str, Template], template: str, what: str, /, **fields: object) -> str:
    """Fill ``templates[template]``: every placeholder must be given and nothing else (strict, so a
    template and its caller cannot drift apart). Values are converted with ``str``; the caller formats
    floats (see ``export.glsl.graph.glsl_float``). Shared by the generated shaders and the baselines'."""
    try:
        tpl = templates[template]
    except KeyError:
        raise KeyError(f"no {what} template named {template!r}") from None
    wanted = set(tpl.get_identifiers())
    given = set(fields)
    if wanted != given:
        raise KeyError(
            f"template {template!r}: missing {sorted(wanted - given)}, unexpected {sorted(given - wanted)}"
        )
    return tpl.substitute({k: str(v) for k, v in fields.items()})


def fill(template: str, /, **fields: object) -> str:
    """Fill the GLSL template named ``template``; every placeholder must be given and nothing else."""
    return fill_from(TEMPLATES, template, "GLSL", **fields)
