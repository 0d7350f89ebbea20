"""Every piece of GLSL and WGSL text neuralao emits, as named templates, and the one function that
fills them.

hls4ml habit: templates here, structure in the writers of ``export/glsl/``, nothing else builds
shader text. Placeholders are ``${name}`` (:class:`string.Template`; ``$`` never occurs in GLSL or
WGSL, so braces need no escaping). :func:`fill` is strict: a missing or an unexpected field is an
error, so a template and its caller cannot drift apart silently.

Values substituted are generated identifiers (``t3``, ``w0_1``, ``src0``), integers and float
literals produced by the writer; ONNX node and tensor names never reach a template.

Dialects (tinygrad's ``cstyle.py`` / ``wgsl.py``): ``_T`` holds the templates every dialect shares,
written once in GLSL with *dialect words* where GLSL and WGSL differ only in spelling; ``_G`` the
GLSL-only ones (fragment MLP, precision statements, the vertex-colour baseline); ``_W`` the WGSL
overrides, only the templates whose structure differs. Each dialect's words (``_WORDS``, and
``_WGSL_WORDS`` over them) are put into its table once, at import:

* ``${vec4}``, ``${ivec2}``, ``${ivec3}``, ``${mat4}``, ``${float}``, ``${int}``: a type, as a
  constructor or a cast spells it (WGSL: ``vec4<f32>``, ``f32``, ...);
* ``${let_T} n`` / ``${var_T} n`` (T one of the types or ``bool``): declare n, a constant or a
  variable (GLSL: ``T n``; WGSL: ``let n`` / ``var n``, the type inferred); ``${let_T:n}`` /
  ``${var_T:n}``: the same with the type written out in WGSL too (``var n: f32``), for loop counters
  and values initialised from a literal or a field;
* ``${fetch}(src, p${lod})``: texel p of ``src`` at level 0; ``${size_of:src}``: its width and
  height; ``${inc:i}``: increment i; ``${precise}``: GLSL's ``precise`` qualifier (none in WGSL).

``_V`` holds the Vulkan GLSL overrides of the GLSL table (compiled to SPIR-V): the version line and the
resource declarations only (set and binding on every resource, sampled images without a sampler, a
uniform block instead of loose uniforms); the bodies are the GLSL ones.

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

_T: dict[str, str] = {}  # every dialect's, in GLSL with dialect words
_G: dict[str, str] = {}  # GLSL only

# --------------------------------------------------------------------------- dialect words

# GLSL's spelling of the words (see the module docstring); WGSL's follow its overrides below.
# ``declare`` / ``declare_typed`` spell ``${let_T}`` / ``${let_T:n}`` for each type T of _TYPES.
_TYPES = ("vec4", "ivec2", "ivec3", "mat4", "float", "int", "bool", "hvec4", "hmat4")
_WORDS: dict[str, str] = {
    "vec4": "vec4",
    "ivec2": "ivec2",
    "ivec3": "ivec3",
    "mat4": "mat4",
    "float": "float",
    "int": "int",
    "bool": "bool",
    # the conv products' types: defined per precision by the pass's arithmetic_* block
    "hvec4": "hvec4",
    "hmat4": "hmat4",
    "declare": "${type}",
    "declare_typed": "${type} ${name}",
    "precise": "precise ",
    "fetch": "texelFetch",
    "lod": ", 0",
    "size_of": "textureSize(${name}, 0).xy",
    "inc": "++${name}",
}

# --------------------------------------------------------------------------- common

_T["header"] = """#version ${version}
${precision}"""

# ES: float, int and sampler default precisions must be raised (sampler2D defaults to lowp in a
# fragment shader, which would truncate RGBA32F texels).
_G["precision_es"] = """precision highp float;
precision highp int;
precision highp sampler2D;"""

_G["precision_none"] = ""

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
_T["act_Relu"] = "max(${x}, ${vec4}(0.0))"
_T["act_LeakyRelu"] = "nao_leaky_relu(${x}, ${alpha})"
_T["act_Sigmoid"] = "nao_sigmoid(${x})"
_T["act_Tanh"] = "nao_tanh(${x})"
# min(max()) rather than clamp(): GLSL leaves clamp undefined for lo > hi; ONNX Clip then gives hi.
_T["act_Clip"] = "min(max(${x}, ${vec4}(${lo})), ${vec4}(${hi}))"
_T["act_Clip_min"] = "max(${x}, ${vec4}(${lo}))"
_T["act_Clip_max"] = "min(${x}, ${vec4}(${hi}))"
_T["act_Identity"] = "${x}"
# Sin / Cos: the builtins (Mesa: Cephes-style range reduction, ~1e-7 absolute for |x| <~ 1e3; the
# field encoding keeps |x| <= 2^(octaves-1) pi and its arguments bit-identical to onnxruntime's).
_T["act_Sin"] = "sin(${x})"
_T["act_Cos"] = "cos(${x})"
# Elu: exp() of min(x, 0) only; Softplus as max(x, 0) + log(1 + exp(-|x|)), so exp() never overflows.
_T["act_Elu"] = "mix(${alpha} * (exp(min(${x}, vec4(0.0))) - 1.0), ${x}, greaterThanEqual(${x}, vec4(0.0)))"
_T["act_Softplus"] = "(max(${x}, ${vec4}(0.0)) + log(1.0 + exp(-abs(${x}))))"
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
_T["act_GeluTanh"] = (
    "(0.5 * ${x} * (1.0 + nao_tanh(0.79788456080286536 * (${x} + 0.044715 * ${x} * ${x} * ${x}))))"
)
_T["act_Mish"] = "(${x} * nao_tanh(max(${x}, ${vec4}(0.0)) + log(1.0 + exp(-abs(${x})))))"
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
_T["act_Pow"] = "pow(${x}, ${vec4}(${e}))"
_T["act_Pow_one"] = "${vec4}(1.0)"
_T["act_Pow_reciprocal"] = "(1.0 / ${x})"
_T["pow_product"] = "(${factors})"

# --------------------------------------------------------------------------- fragment MLP

_G["fullscreen_vertex"] = """${header}
// neuralao: full-screen triangle from gl_VertexID; draw 3 vertices with an empty VAO.
void main() {
    vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""

_G["sampler2d_decl"] = "uniform sampler2D ${name};"
_G["sampler2d_decl_binding"] = "layout(binding = ${binding}) uniform sampler2D ${name};"

_G["ubo_block"] = """${layout}uniform ${block} {
${members}
};"""
_G["ubo_layout"] = "layout(std140) "
_G["ubo_layout_binding"] = "layout(std140, binding = ${binding}) "
_G["ubo_member"] = "    ${type} ${name}[${count}];"

_G["vector_fragment"] = """${header}
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

_G["weights_uniform"] = "weights in ${n_blocks} std140 uniform block(s), each <= ${max_block_bytes} bytes."
_G["weights_constant"] = "weights as const arrays in this source (nothing to bind)."
_G["const_array"] = "const ${type} ${name}[${count}] = ${type}[${count}](${items});"
_G["const_item"] = "${type}(${values})"

_G["texel_fetch"] = "    vec4 g${index} = texelFetch(${sampler}, ivec2(gl_FragCoord.xy), 0);"

_G["vec_decl"] = "    vec4 ${name}[${count}];"
_G["input_tile"] = "    ${dst}[${index}] = vec4(${c0}, ${c1}, ${c2}, ${c3});"

# Dense layers, straight-line: output vec4 j = act(bias[j] + sum_i tile[j, i] * src[i]) (mat4 tiles).
_G["mat_term"] = "${weight}[${index}] * ${src}[${i}]"
_G["dense_acc"] = "(${bias}[${j}] + ${terms})"
_G["dense_row"] = "    ${dst}[${j}] = ${value};"
# A large layer: the rows of a chunk in a loop whose bound reads u_loop_guard (always 0: uniforms start
# at 0; never set it), so the compiler cannot see a constant trip count and unroll it.
_G["dense_loop"] = """    for (int j = ${j_begin}; j < ${j_end} + u_loop_guard; ++j) {
    ${row}
    }"""

_G["vec_map"] = "    ${dst}[${j}] = ${expr};"

_G["index_j"] = "${name}[${j}]"
_G["binop"] = "(${a} ${op} ${b})"
_G["vec_copy"] = "    ${dst}[${di}] = ${src}[${si}];"
_G["lane_copy"] = "    ${dst}[${di}].${dl} = ${src}[${si}].${sl};"
_G["lane_zero"] = "    ${dst}[${di}].${dl} = 0.0;"
_G["index_0"] = "${name}[0]"

# --------------------------------------------------------------------------- compute passes

_T["compute_pass"] = """${header}
${arithmetic}
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
    imageStore(dst, ivec3(${store_xy}, gid.z), r);
}
"""

# The types of a dense conv's products (hvec4, hmat4): fp32, or fp16 where the compiler has a half
# type (GL: GL_EXT_shader_explicit_arithmetic_types_float16 or GL_AMD_gpu_shader_half_float; Vulkan:
# the first, with the device feature shaderFloat16), else fp32 (the preprocessor picks; no driver
# refuses the shader). Weights and texels are converted as they are read; each weight matrix times
# texel is summed into an fp32 accumulator (a sum of hundreds of terms in fp16 drifts by several 8-bit
# AO steps in a trained U-Net); epilogues run in fp32.
_T["arithmetic_fp32"] = """// conv products: fp32
#define hvec4 vec4
#define hmat4 mat4"""
_T["arithmetic_fp16"] = """// conv products: fp16 where the compiler has a half type, else fp32 (sums in fp32)
#extension GL_EXT_shader_explicit_arithmetic_types_float16 : enable
#extension GL_AMD_gpu_shader_half_float : enable
#if defined(GL_EXT_shader_explicit_arithmetic_types_float16) || defined(GL_AMD_gpu_shader_half_float)
#define hvec4 f16vec4
#define hmat4 f16mat4
#else
#define hvec4 vec4
#define hmat4 mat4
#endif"""
_T["sampler_array_decl"] = "layout(binding = ${binding}) uniform highp sampler2DArray ${name};"
_T["image_array_decl"] = "layout(binding = ${binding}, ${format}) writeonly uniform highp image2DArray dst;"
_T["params_decl"] = """layout(std430, binding = ${binding}) readonly buffer Params {
    vec4 prm[];
};"""
_T["uniform_int_decl"] = "layout(location = ${slot}) uniform int ${name};"
_T["uniform_float_decl"] = "layout(location = ${slot}) uniform float ${name};"
_T["storage_format_rgba32f"] = "rgba32f"
_T["storage_format_rgba16f"] = "rgba16f"
_T["size_decl"] = "    ivec2 ${size} = textureSize(${src}, 0).xy;"

# Conv: one invocation = one output texel (4 output channels of layer gid.z).
_T["conv_body"] = """${sizes}
    ${var_vec4} acc = prm[${bias_offset} + gid.z];
${taps}
    ${var_vec4} r = ${vec4}(acc);"""
# The taps of a conv's input parts read tap by tap (conv_input_loop and conv_input_loop_fused).
_T["conv_tap_loops"] = """    for (${var_int:ky} = 0; ky < ${kh}; ${inc:ky}) {
        ${let_int} iy = gid.y * ${sy} - ${pad_top} + ky * ${dy};
        for (${var_int:kx} = 0; kx < ${kw}; ${inc:kx}) {
            ${let_int} ix = gid.x * ${sx} - ${pad_left} + kx * ${dx};
            ${let_int} tap = ${weight_offset} + ((gid.z * ${kh} + ky) * ${kw} + kx) * ${tap_stride};
${input_loops}
        }
    }"""

# A 3x3 conv (stride 1, pads 1) reading ${src} upsampled x2 (bilinear, half_pixel): the upsampled texels
# of its 9 taps blend the 3x3 low texels around gid / 2, fetched once per input layer (a tap read alone
# fetches 4: conv_read_up2). Tap column k of an even x blends low columns (0, 1), (0, 1), (1, 2) with
# weights 1/4, 3/4, 1/4 on the second; of an odd x (0, 1), (1, 2), (1, 2) with 3/4, 1/4, 3/4; rows alike.
# The edge clamp of the resize is the clamp of the low coordinates; taps outside the upsampled image
# (vx0, vx2, vy0, vy2) contribute nothing, as the zero padding.
_T["conv_up2_taps"] = """    {
        // input part ${part}: ${src} upsampled x2, its 3x3 taps from 3x3 low texels
        ${let_ivec2} lo = ${src_size} - 1;
        ${let_ivec2} m = gid.xy / 2;
        ${let_bool} ox = (gid.x & 1) == 1;
        ${let_bool} oy = (gid.y & 1) == 1;
        ${let_int} x0 = clamp(m.x - 1, 0, lo.x);
        ${let_int} x1 = clamp(m.x, 0, lo.x);
        ${let_int} x2 = clamp(m.x + 1, 0, lo.x);
        ${let_int} y0 = clamp(m.y - 1, 0, lo.y);
        ${let_int} y1 = clamp(m.y, 0, lo.y);
        ${let_int} y2 = clamp(m.y + 1, 0, lo.y);
        ${let_float} wx = ${wx};
        ${let_float} wy = ${wy};
        ${let_bool} vx0 = gid.x >= 1;
        ${let_bool} vx2 = gid.x + 1 < ${size}.x;
        ${let_bool} vy0 = gid.y >= 1;
        ${let_bool} vy2 = gid.y + 1 < ${size}.y;
        for (${var_int:l} = 0; l < ${layers}; ${inc:l}) {
${fetches}
${blends}
            ${let_int} o = ${weight_offset} + gid.z * 9 * ${tap_stride} + (${layer_offset} + l) * 4;
${taps}
        }
    }"""
_T["conv_up2_fetch"] = (
    "            ${let_vec4} c${i}${j} = ${fetch}(${src}, ${ivec3}(x${j}, y${i}, l)${lod});"
)
_T["conv_up2_blend"] = "            ${let_vec4} ${name} = mix(${a}, ${b}, ${w});"
_T["conv_up2_tap"] = """            if (${valid}) {
                ${let_int} t${k} = o + ${k} * ${tap_stride};
                ${let_mat4} w${k} = ${mat4}(prm[t${k}], prm[t${k} + 1], prm[t${k} + 2], prm[t${k} + 3]);
                acc += ${vec4}(${hmat4}(w${k}) * ${hvec4}(${u}));
            }"""
# cond ? a : b, for any type
_T["pick"] = "(${cond} ? ${a} : ${b})"

# Zero padding: taps outside the input contribute nothing (texelFetch outside is undefined).
_T["conv_input_loop"] = """            if (iy >= 0 && iy < ${size}.y && ix >= 0 && ix < ${size}.x) {
                for (${var_int:l} = 0; l < ${layers}; ${inc:l}) {
                    ${let_vec4} v = ${fetch}(${src}, ${ivec3}(ix, iy, l)${lod});
                    ${let_int} o = tap + (${layer_offset} + l) * 4;
                    ${let_mat4} w = ${mat4}(prm[o], prm[o + 1], prm[o + 2], prm[o + 3]);
                    acc += ${vec4}(${hmat4}(w) * ${hvec4}(v));
                }
            }"""

# A conv input read through a pass fused into the conv (gpu preset): ``${src}`` holds the pass's
# source, ``${src_size}`` its size, ``${size}`` the size the conv sees (the fused pass's output). The
# read is the fused pass's arithmetic in the same order: AveragePool 2x2 stride 2 ("pool2": the
# window's sum in row order, then / 4) or Resize x2 linear half_pixel ("up2": the resize_linear_body
# source coordinate, exact here, and blend).
_T["size_halved"] = "    ${let_ivec2} ${size} = ${src_size} / 2;"
_T["size_doubled"] = "    ${let_ivec2} ${size} = ${src_size} * 2;"
_T["conv_input_loop_fused"] = """            if (iy >= 0 && iy < ${size}.y && ix >= 0 && ix < ${size}.x) {
${setup}
                for (${var_int:l} = 0; l < ${layers}; ${inc:l}) {
                    ${let_vec4} v = ${read};
                    ${let_int} o = tap + (${layer_offset} + l) * 4;
                    ${let_mat4} w = ${mat4}(prm[o], prm[o + 1], prm[o + 2], prm[o + 3]);
                    acc += ${vec4}(${hmat4}(w) * ${hvec4}(v));
                }
            }"""
_T["conv_setup_pool2"] = (
    "                // input texel (ix, iy): the mean of ${src}'s 2x2 texels from (2 ix, 2 iy)"
)
_T["conv_read_pool2"] = """(${fetch}(${src}, ${ivec3}(2 * ix, 2 * iy, l)${lod})
                        + ${fetch}(${src}, ${ivec3}(2 * ix + 1, 2 * iy, l)${lod})
                        + ${fetch}(${src}, ${ivec3}(2 * ix, 2 * iy + 1, l)${lod})
                        + ${fetch}(${src}, ${ivec3}(2 * ix + 1, 2 * iy + 1, l)${lod})) / 4.0"""
_T["conv_setup_up2"] = """                // input texel (ix, iy): ${src} upsampled x2 (bilinear, half_pixel)
                ${let_float} fy = clamp(${float}(iy) * 0.5 - 0.25, 0.0, ${float}(${src_size}.y - 1));
                ${let_float} fx = clamp(${float}(ix) * 0.5 - 0.25, 0.0, ${float}(${src_size}.x - 1));
                ${let_int} y0 = ${int}(fy);
                ${let_int} x0 = ${int}(fx);
                ${let_int} y1 = min(y0 + 1, ${src_size}.y - 1);
                ${let_int} x1 = min(x0 + 1, ${src_size}.x - 1);
                ${let_float} wy = fy - ${float}(y0);
                ${let_float} wx = fx - ${float}(x0);"""
# The network's input read in place of the pad pass (reflect at the bottom/right, as pad_reflect_body):
# (ix, iy) below the padded size ${size} maps into the ${src_size} input, rows flipped by u_flip_y.
_T["size_padded"] = "    ${let_ivec2} ${size} = (${src_size} + ${below}) / ${multiple} * ${multiple};"
_T[
    "conv_setup_reflect"
] = """                // input texel (ix, iy): ${src} reflect-padded at the bottom/right to ${size}
                ${let_int} rx = clamp(${src_size}.x - 1 - abs(${src_size}.x - 1 - ix), 0, ${src_size}.x - 1);
                ${var_int:ry} = clamp(${src_size}.y - 1 - abs(${src_size}.y - 1 - iy), 0, ${src_size}.y - 1);
                if (u_flip_y != 0) {
                    ry = ${src_size}.y - 1 - ry;  // the input is stored bottom-up (a GL render target)
                }"""
_T["conv_read_reflect"] = "${fetch}(${src}, ${ivec3}(rx, ry, l)${lod})"
# ... with the pad pass's guard: lanes past the last channel read as 0 whatever they hold (NaN too).
_T["conv_read_reflect_guard"] = (
    "mix(vec4(0.0), ${fetch}(${src}, ${ivec3}(rx, ry, l)${lod}), "
    "lessThan(ivec4(4 * l) + ivec4(0, 1, 2, 3), ivec4(${channels})))"
)
_T["conv_read_up2"] = """(${fetch}(${src}, ${ivec3}(x0, y0, l)${lod}) * (1.0 - wx)
                        + ${fetch}(${src}, ${ivec3}(x1, y0, l)${lod}) * wx) * (1.0 - wy)
                        + (${fetch}(${src}, ${ivec3}(x0, y1, l)${lod}) * (1.0 - wx)
                        + ${fetch}(${src}, ${ivec3}(x1, y1, l)${lod}) * wx) * wy"""

# Conv, blocked: one invocation = a ${block_x} x ${block_y} block of output texels x ${block_layers}
# output layers (z0 = block_layers * gid.z ..). Each input texel fetched feeds every output layer of
# the block and each mat4 of weights every texel of it; accumulators a<o>_<p> are straight-line
# registers (layer o, texel p), the tap and input-layer loops stay loops. Helper functions keep the
# source short (the compiler inlines them).
_T["compute_pass_block"] = """${header}
${arithmetic}
// neuralao compute pass ${pass_index}: ${summary}
// One invocation: ${block_x}x${block_y} output texels x ${block_layers} output layer(s) \
from layer ${block_layers} * gid.z.
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
        imageStore(dst, ivec3(${store_xy}, z), r);
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

_T["conv_block_body"] = """    ${let_ivec2} in_size = ${size_of:src0};
${acc_init}
    for (${var_int:ky} = 0; ky < ${kh}; ${inc:ky}) {
        for (${var_int:kx} = 0; kx < ${kw}; ${inc:kx}) {
            ${let_int} tap = ${weight_offset} + ((z0 * ${kh} + ky) * ${kw} + kx) * ${tap_stride};
            ${let_ivec2} qb = base * ${ivec2}(${sx}, ${sy}) + \
${ivec2}(kx * ${dx} - ${pad_left}, ky * ${dy} - ${pad_top});
${coords}
${input_loops}
        }
    }"""
_T["conv_block_bias"] = "    ${let_vec4} b${o} = prm[${bias_offset} + z0 + ${o}];"
_T["conv_block_acc"] = "    ${var_vec4} ${names};"
_T["conv_block_acc_name"] = "a${o}_${p} = b${o}"
_T["conv_block_acc_sep"] = ", "
_T["conv_block_coord"] = (
    "            ivec2 q${p} = qb + ivec2(${qx}, ${qy}); float k${p} = nao_clip(q${p}, in_size);"
)
_T["conv_block_input_loop"] = """            for (${var_int:l} = 0; l < ${layers}; ${inc:l}) {
                ${let_int} o = tap + (${layer_offset} + l) * 4;
${fetches}
${products}
            }"""
_T["conv_block_fetch"] = (
    "                ${let_hvec4} v${p} = ${hvec4}(${fetch}(${src}, ${ivec3}(q${p}, l)${lod}) * k${p});"
)
_T["conv_block_weight"] = "                ${let_hmat4} m${o} = ${hmat4}(nao_tap(o + ${off}));"
_T["conv_block_fma"] = "a${o}_${p} += ${vec4}(m${o} * v${p});"
_T["conv_block_fmas"] = "                ${fmas}"
_T["conv_block_store"] = "    nao_store(base + ${ivec2}(${px}, ${py}), z0 + ${o}, ${vec4}(a${o}_${p}));"

# ConvTranspose as a gather: output y takes input iy where y = iy * stride - pad + ky * dilation.
_T["conv_transpose_body"] = """${sizes}
    ${var_vec4} acc = prm[${bias_offset} + gid.z];
    for (${var_int:ky} = 0; ky < ${kh}; ${inc:ky}) {
        ${let_int} ty = gid.y + ${pad_top} - ky * ${dy};
        if (ty < 0 || ty % ${sy} != 0) {
            continue;
        }
        ${let_int} iy = ty / ${sy};
        for (${var_int:kx} = 0; kx < ${kw}; ${inc:kx}) {
            ${let_int} tx = gid.x + ${pad_left} - kx * ${dx};
            if (tx < 0 || tx % ${sx} != 0) {
                continue;
            }
            ${let_int} ix = tx / ${sx};
            ${let_int} tap = ${weight_offset} + ((gid.z * ${kh} + ky) * ${kw} + kx) * ${tap_stride};
${input_loops}
        }
    }
    ${var_vec4} r = ${vec4}(acc);"""

# Depthwise conv (group = channels): output layer gid.z reads input layer gid.z only, one vec4 per tap.
_T["conv_depthwise_body"] = """    ${let_ivec2} in_size = ${size_of:src0};
    ${var_vec4} r = prm[${bias_offset} + gid.z];
    for (${var_int:ky} = 0; ky < ${kh}; ${inc:ky}) {
        ${let_int} iy = gid.y * ${sy} - ${pad_top} + ky * ${dy};
        if (iy < 0 || iy >= in_size.y) {
            continue;
        }
        for (${var_int:kx} = 0; kx < ${kw}; ${inc:kx}) {
            ${let_int} ix = gid.x * ${sx} - ${pad_left} + kx * ${dx};
            if (ix < 0 || ix >= in_size.x) {
                continue;
            }
            r += prm[${weight_offset} + (gid.z * ${kh} + ky) * ${kw} + kx] * \
${fetch}(src0, ${ivec3}(ix, iy, gid.z)${lod});
        }
    }"""

# count: taps inside the input; count_padded: taps inside the padded input (ceil_mode windows may
# reach past the trailing pads; count_include_pad divides by count_padded, as onnxruntime does).
_T["pool_body"] = """    ${let_ivec2} in_size = ${size_of:src0};
    ${var_vec4} r = ${init};
    ${var_int:count} = 0;
    ${var_int:count_padded} = 0;
    for (${var_int:ky} = 0; ky < ${kh}; ${inc:ky}) {
        ${let_int} iy = gid.y * ${sy} - ${pad_top} + ky * ${dy};
        if (iy < -${pad_top} || iy >= in_size.y + ${pad_bottom}) {
            continue;
        }
        for (${var_int:kx} = 0; kx < ${kw}; ${inc:kx}) {
            ${let_int} ix = gid.x * ${sx} - ${pad_left} + kx * ${dx};
            if (ix < -${pad_left} || ix >= in_size.x + ${pad_right}) {
                continue;
            }
            count_padded += 1;
            if (iy < 0 || iy >= in_size.y || ix < 0 || ix >= in_size.x) {
                continue;
            }
            ${let_vec4} v = ${fetch}(src0, ${ivec3}(ix, iy, gid.z)${lod});
            r = ${accumulate};
            count += 1;
        }
    }
${finish}"""
_T["pool_init_avg"] = "${vec4}(0.0)"
_T["pool_init_max"] = "${vec4}(-3.402823466e+38)"
_T["pool_acc_avg"] = "r + v"
_T["pool_acc_max"] = "max(r, v)"
_T["pool_finish_count"] = "    r /= ${float}(max(count, 1));"
_T["pool_finish_padded"] = "    r /= ${float}(max(count_padded, 1));"
_T["pool_finish_none"] = "    // max pool: no normalisation"
# Lp pools: the sum of |x|^p over the window (padding adds nothing), then its p-th root.
_T["pool_init_lp"] = "${vec4}(0.0)"
_T["pool_acc_l1"] = "r + abs(v)"
_T["pool_acc_l2"] = "r + v * v"
_T["pool_acc_lp"] = "r + pow(abs(v), ${vec4}(${p}))"
_T["pool_finish_l1"] = "    // L1: the sum itself"
_T["pool_finish_l2"] = "    r = sqrt(r);"
_T["pool_finish_lp"] = "    r = pow(r, ${vec4}(${inv_p}));"

# Global pools: one invocation per output layer walks the whole input (the output is 1 x 1).
_T["global_pool_body"] = """    ${let_ivec2} in_size = ${size_of:src0};
    ${var_vec4} r = ${init};
    for (${var_int:iy} = 0; iy < in_size.y; ${inc:iy}) {
        for (${var_int:ix} = 0; ix < in_size.x; ${inc:ix}) {
            ${let_vec4} v = ${fetch}(src0, ${ivec3}(ix, iy, gid.z)${lod});
            r = ${accumulate};
        }
    }
${finish}"""
_T["global_finish_mean"] = "    r /= ${float}(in_size.x * in_size.y);"

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
    "(${len_in} * 0.5 * (1.0 - nao_div(${len_out}, ${scale} * ${len_in})) + "
    "nao_div(${x} + 0.5, ${scale}) - 0.5)"
)
# tf_crop_and_resize: roi start / end literals of this axis, in onnxruntime's operation order.
_T["coord_tf_crop_and_resize"] = (
    "(${len_out} > 1.0 ? ${start} * (${len_in} - 1.0) + "
    "nao_div(${x} * (${end} - ${start}) * (${len_in} - 1.0), "
    "${len_out} - 1.0) : 0.5 * (${start} + ${end}) * (${len_in} - 1.0))"
)
_T["scale_literal"] = "${value}"
_T["scale_ratio"] = "nao_div(${len_out}, ${len_in})"
_T["float_of"] = "${float}(${v})"

# Nearest index per nearest_mode, exact for non-negative coordinates (negative ones clamp to 0).
_T["round_round_prefer_floor"] = "(fract(${v}) > 0.5 ? ceil(${v}) : floor(${v}))"
_T["round_round_prefer_ceil"] = "(fract(${v}) >= 0.5 ? ceil(${v}) : floor(${v}))"
_T["round_floor"] = "floor(${v})"
_T["round_ceil"] = "ceil(${v})"

_T["resize_linear_body"] = """    ${let_ivec2} in_size = ${size_of:src0};
    ${precise}${var_float:fy} = ${coord_y};
    ${precise}${var_float:fx} = ${coord_x};
${outside}
    fy = clamp(fy, 0.0, ${float}(in_size.y - 1));
    fx = clamp(fx, 0.0, ${float}(in_size.x - 1));
    ${let_int} y0 = ${int}(fy);
    ${let_int} x0 = ${int}(fx);
    ${let_int} y1 = min(y0 + 1, in_size.y - 1);
    ${let_int} x1 = min(x0 + 1, in_size.x - 1);
    ${let_float} wy = fy - ${float}(y0);
    ${let_float} wx = fx - ${float}(x0);
    ${let_vec4} a = ${fetch}(src0, ${ivec3}(x0, y0, gid.z)${lod});
    ${let_vec4} b = ${fetch}(src0, ${ivec3}(x1, y0, gid.z)${lod});
    ${let_vec4} c = ${fetch}(src0, ${ivec3}(x0, y1, gid.z)${lod});
    ${let_vec4} d = ${fetch}(src0, ${ivec3}(x1, y1, gid.z)${lod});
    ${var_vec4} r = (a * (1.0 - wx) + b * wx) * (1.0 - wy) + (c * (1.0 - wx) + d * wx) * wy;
    if (outside) {
        r = ${vec4}(${extrapolation});
    }"""

_T["resize_nearest_body"] = """    ${let_ivec2} in_size = ${size_of:src0};
    ${precise}${let_float:fy} = ${coord_y};
    ${precise}${let_float:fx} = ${coord_x};
${outside}
    ${let_int} iy = clamp(${int}(${round_y}), 0, in_size.y - 1);
    ${let_int} ix = clamp(${int}(${round_x}), 0, in_size.x - 1);
    ${var_vec4} r = ${fetch}(src0, ${ivec3}(ix, iy, gid.z)${lod});
    if (outside) {
        r = ${vec4}(${extrapolation});
    }"""

# tf_crop_and_resize: a source coordinate outside the input gives extrapolation_value.
_T["resize_outside"] = (
    "    ${let_bool} outside = "
    "fy < 0.0 || fy > ${float}(in_size.y - 1) || fx < 0.0 || fx > ${float}(in_size.x - 1);"
)
_T["resize_inside"] = "    const bool outside = false;"

# Separable filter (cubic, or linear / cubic widened by 1 / scale when antialiasing a downscale):
# taps floor(f) - half + 1 .. floor(f) + half per axis, weights normalised by their sum (onnxruntime).
_T["resize_filter_body"] = """    ${let_ivec2} in_size = ${size_of:src0};
    ${precise}${let_float:fy} = ${coord_y};
    ${precise}${let_float:fx} = ${coord_x};
${outside}
    ${let_int} y_first = ${int}(floor(fy)) - ${half_y} + 1;
    ${let_int} x_first = ${int}(floor(fx)) - ${half_x} + 1;
    ${var_vec4} acc = ${vec4}(0.0);
    ${var_float:wsum} = 0.0;
    for (${var_int:j} = 0; j < ${taps_y}; ${inc:j}) {
        ${var_int} iy = y_first + j;
        ${var_float:wy} = ${weight_y};
${exclude_y}
        iy = clamp(iy, 0, in_size.y - 1);
        for (${var_int:i} = 0; i < ${taps_x}; ${inc:i}) {
            ${var_int} ix = x_first + i;
            ${var_float:wx} = ${weight_x};
${exclude_x}
            ix = clamp(ix, 0, in_size.x - 1);
            acc += (wy * wx) * ${fetch}(src0, ${ivec3}(ix, iy, gid.z)${lod});
            wsum += wy * wx;
        }
    }
    ${var_vec4} r = acc / wsum;
    if (outside) {
        r = ${vec4}(${extrapolation});
    }"""
_T["filter_arg"] = "((${float}(${i}) - ${f}) * ${widen})"
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

_T["concat_body"] = """    ${var_vec4} r = ${vec4}(0.0);
    for (${var_int:lane} = 0; lane < 4; ${inc:lane}) {
        ${let_int} c = gid.z * 4 + lane;
${branches}
    }"""
_T["concat_branch"] = """        if (c >= ${begin} && c < ${end}) {
            r[lane] = ${fetch}(${src}, ${ivec3}(gid.xy, (c - ${begin}) / 4)${lod})[(c - ${begin}) % 4];
        }"""

# A scalar graph input (a uniform) as a 1x1 one-channel texture; the padding lanes hold 0.
_T["uniform_body"] = "    ${var_vec4} r = ${vec4}(${name}, 0.0, 0.0, 0.0);"

_T["elementwise_body"] = "    ${var_vec4} r = ${fetch}(src0, gid${lod});"

# Two images a (src0) and b (src1); a 1x1 or one-channel operand is broadcast.
_T["binary_body"] = """    ${let_vec4} a = ${fetch_a};
    ${var_vec4} b = ${fetch_b};
${guard}
    ${var_vec4} r = ${expr};"""
_T["fetch_full"] = "${fetch}(${src}, gid${lod})"
_T["fetch_pixel"] = "${fetch}(${src}, ${ivec3}(0, 0, gid.z)${lod})"
_T["fetch_channel"] = "${fetch}(${src}, ${ivec3}(gid.xy, 0)${lod}).xxxx"
_T["fetch_scalar"] = "${fetch}(${src}, ${ivec3}(0)${lod}).xxxx"
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

# A pointwise group (passes computed inside their reader): member k's layers at this texel in a local
# array v<k>, each from the group's inputs or an earlier member's array; the pass stores v<last>[gid.z].
_T["pointwise_array"] = "    vec4 ${name}[${n}];"
_T["pointwise_layer"] = """    {
${body}
${epilogue}
        ${name}[${layer}] = r;
    }"""
_T["pointwise_copy"] = "    ${var_vec4} r = ${x};"
_T["pointwise_conv"] = """    ${var_vec4} r = prm[${bias}];
${terms}"""
_T["pointwise_conv_term"] = "    r += ${mat4}(prm[${o}], prm[${o} + 1], prm[${o} + 2], prm[${o} + 3]) * ${x};"
_T["pointwise_result"] = "    ${var_vec4} r = ${name}[gid.z];"
# A group reading the network's input in place of the pad pass: its texel (rx, ry), as conv_setup_reflect
# maps it (the reflection at the bottom/right, rows flipped by u_flip_y); the guard zeroes the lanes past
# the last channel, as the pad pass's guard does.
_T["pointwise_reflect_setup"] = """    ${let_int} ix = gid.x;
    ${let_int} iy = gid.y;
""" + _T["conv_setup_reflect"].replace("\n            ", "\n").replace("                ", "    ", 1)
_T["pointwise_reflect"] = "${fetch}(${src}, ${ivec3}(rx, ry, ${layer})${lod})"
_T["pointwise_reflect_guard"] = (
    "mix(vec4(0.0), ${fetch}(${src}, ${ivec3}(rx, ry, ${layer})${lod}), "
    "lessThan(ivec4(4 * ${layer}) + ivec4(0, 1, 2, 3), ivec4(${channels})))"
)

# ONNX Pad on H, W (negative pads crop): output texel (x, y) reads input (x - left, y - top).
_T["spatial_pad_body"] = """    ${let_ivec2} in_size = ${size_of:src0};
    ${var_int} x = gid.x - ${left};
    ${var_int} y = gid.y - ${top};
${mode}"""
_T["pad_constant"] = """    ${var_vec4} r = ${vec4}(${value});
    if (x >= 0 && x < in_size.x && y >= 0 && y < in_size.y) {
        r = ${fetch}(src0, ${ivec3}(x, y, gid.z)${lod});
    }"""
_T["pad_edge"] = (
    "    ${var_vec4} r = "
    "${fetch}(src0, ${ivec3}(clamp(x, 0, in_size.x - 1), clamp(y, 0, in_size.y - 1), gid.z)${lod});"
)
# Reflect (edge sample not repeated) for any pad width: fold |x| into one period 2 (n - 1).
_T["pad_reflect"] = """    ${let_ivec2} period = max(2 * (in_size - 1), ${ivec2}(1));
    ${let_ivec2} m = abs(${ivec2}(x, y)) % period;
    ${var_vec4} r = ${fetch}(src0, ${ivec3}(min(m, period - m), gid.z)${lod});"""
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
# A two-image op fused into the conv producing one operand (r): the other operand is a texel of an
# input at the output texel ${xy}, layer ${z} (or broadcast), as the binary pass would fetch it.
_T["epilogue_binary"] = """    {
        ${let_vec4} a = ${a};
        ${var_vec4} b = ${b};
${guard}
        r = ${expr};
    }"""
_T["epilogue_guard_div"] = (
    "        b = mix(vec4(1.0), b, lessThan(ivec4(4 * ${z}) + ivec4(0, 1, 2, 3), ivec4(${channels})));"
)
_T["side_full"] = "${fetch}(${src}, ${ivec3}(${xy}, ${z})${lod})"
_T["side_pixel"] = "${fetch}(${src}, ${ivec3}(0, 0, ${z})${lod})"
_T["side_channel"] = "${fetch}(${src}, ${ivec3}(${xy}, 0)${lod}).xxxx"
_T["side_scalar"] = "${fetch}(${src}, ${ivec3}(0)${lod}).xxxx"
# A crop fused into the pass producing its input: texel xy stored row-flipped when u_flip_y is set
# (a bottom-up engine texture); ${size} is the output's size.
_T["flip_xy"] = "ivec2(${xy}.x, u_flip_y != 0 ? ${size}.y - 1 - ${xy}.y : ${xy}.y)"
_T["dst_size"] = "imageSize(dst).xy"
# Padding lanes (channels >= ${channels}) to 0 after an activation that could make them inf or NaN.
_T["epilogue_guard"] = (
    "    r = mix(vec4(0.0), r, lessThan(ivec4(4 * ${z}) + ivec4(0, 1, 2, 3), ivec4(${channels})));"
)

# Gather (a view materialised: DepthToSpace, SpaceToDepth, channel shuffles, transposes): each output
# coordinate is split into its digits, innermost first; each digit moves one source coordinate (s.z:
# the channel) by its stride. The outermost digit of an axis takes the rest of the index (no modulo).
_T["gather_body"] = """    ${var_vec4} r = ${vec4}(0.0);
    for (${var_int:lane} = 0; lane < 4; ${inc:lane}) {
        ${let_int} c = gid.z * 4 + lane;
        if (c >= ${channels}) {
            break;
        }
        ${var_ivec3} s = ${ivec3}(0);  // source x, y, channel
        ${var_int} v = c;
${digits_c}
        v = gid.y;
${digits_y}
        v = gid.x;
${digits_x}
        r[lane] = ${fetch}(src0, ${ivec3}(s.xy, s.z / 4)${lod})[s.z % 4];
    }"""
_T["gather_digit"] = """        s.${coord} += (v % ${size}) * ${stride};
        v /= ${size};"""
_T["gather_digit_last"] = "        s.${coord} += v * ${stride};"

# Member loops of a reduction (reduce, moments): the pixels of the output texel's window (the whole
# image on a reduced axis) x the members of channel group g (prm tables: base per group, offsets).
_T["member_loops"] = """        for (${var_int:iy} = ${y_begin}; iy < ${y_end}; ${inc:iy}) {
            for (${var_int:ix} = ${x_begin}; ix < ${x_end}; ${inc:ix}) {
                for (${var_int:k} = 0; k < ${members}; ${inc:k}) {
                    ${let_int} c = base + ${int}(prm[${offsets_offset} + k / 4][k % 4]);
                    ${let_float} v = ${fetch}(src0, ${ivec3}(ix, iy, c / 4)${lod})[c % 4];
                    ${statement}
                }
            }
        }"""
_T["reduce_body"] = """    ${let_ivec2} in_size = ${size_of:src0};
    ${var_vec4} r = ${vec4}(0.0);
    for (${var_int:lane} = 0; lane < 4; ${inc:lane}) {
        ${let_int} g = gid.z * 4 + lane;
        if (g >= ${groups}) {
            break;
        }
        ${let_int} base = ${int}(prm[${base_offset} + g / 4][g % 4]);
        ${let_float} n = ${float}(${members} * (${y_end} - ${y_begin}) * (${x_end} - ${x_begin}));
        ${var_float:s} = ${init};
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
_T["moments_body"] = """    ${let_ivec2} in_size = ${size_of:src0};
    ${var_vec4} r = ${vec4}(0.0);
    for (${var_int:lane} = 0; lane < 4; ${inc:lane}) {
        ${let_int} j = gid.z * 4 + lane;
        if (j >= ${channels}) {
            break;
        }
        ${let_int} g = j % ${groups};
        ${let_int} base = ${int}(prm[${base_offset} + g / 4][g % 4]);
        ${let_float} n = ${float}(${members} * (${y_end} - ${y_begin}) * (${x_end} - ${x_begin}));
        ${var_float:s} = 0.0;
${sum_loops}
        ${let_float} mean = s / n;
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
_T["normalize_body"] = """    ${let_vec4} x = ${fetch}(src0, gid${lod});
    ${var_vec4} r = ${vec4}(0.0);
    for (${var_int:lane} = 0; lane < 4; ${inc:lane}) {
        ${let_int} g = ${int}(prm[${group_offset} + gid.z][lane]);
        ${let_int} h = g + ${groups};
        ${let_float} mean = ${fetch}(src1, ${ivec3}(${stats_x}, ${stats_y}, g / 4)${lod})[g % 4];
        ${let_float} rstd = ${fetch}(src1, ${ivec3}(${stats_x}, ${stats_y}, h / 4)${lod})[h % 4];
        r[lane] = (x[lane] - mean) * rstd;
    }"""

# Softmax over the channels of a group at one pixel (prm: the group's first channel per channel, offsets).
_T["softmax_body"] = """    ${let_vec4} x = ${fetch}(src0, gid${lod});
    ${var_vec4} r = ${vec4}(0.0);
    for (${var_int:lane} = 0; lane < 4; ${inc:lane}) {
        ${let_int} c = gid.z * 4 + lane;
        if (c >= ${channels}) {
            break;
        }
        ${let_int} base = ${int}(prm[${base_offset} + gid.z][lane]);
        ${var_float:m} = -3.402823466e+38;
        for (${var_int:k} = 0; k < ${members}; ${inc:k}) {
            ${let_int} q = base + ${int}(prm[${offsets_offset} + k / 4][k % 4]);
            m = max(m, ${fetch}(src0, ${ivec3}(gid.xy, q / 4)${lod})[q % 4]);
        }
        ${var_float:s} = 0.0;
        for (${var_int:k} = 0; k < ${members}; ${inc:k}) {
            ${let_int} q = base + ${int}(prm[${offsets_offset} + k / 4][k % 4]);
            s += exp(${fetch}(src0, ${ivec3}(gid.xy, q / 4)${lod})[q % 4] - m);
        }
        r[lane] = ${finish};
    }"""
_T["softmax_finish"] = "exp(x[lane] - m) / s"
_T["log_softmax_finish"] = "x[lane] - m - log(s)"

# LRN across channels: x / (bias + alpha / size * sum of squares over the window) ^ beta.
_T["lrn_body"] = """    ${let_vec4} x = ${fetch}(src0, gid${lod});
    ${var_vec4} r = ${vec4}(0.0);
    for (${var_int:lane} = 0; lane < 4; ${inc:lane}) {
        ${let_int} c = gid.z * 4 + lane;
        if (c >= ${channels}) {
            break;
        }
        ${var_float:s} = 0.0;
        for (${var_int:k} = max(c - ${before}, 0); k <= min(c + ${after}, ${channels} - 1); ${inc:k}) {
            ${let_float} v = ${fetch}(src0, ${ivec3}(gid.xy, k / 4)${lod})[k % 4];
            s += v * v;
        }
        r[lane] = x[lane] / pow(${bias} + ${alpha} * s, ${beta});
    }"""

# --------------------------------------------------------------------------- baseline: vertex-colour AO

# The cheapest AO an engine can draw (baked per-vertex values, Sloan et al. style), used by the
# benchmark as the reference cost next to the MLP pass.
_G["vertex_colour_vert"] = """${header}
layout(location = 0) in vec3 a_position;
layout(location = 1) in float a_ao;
uniform mat4 u_mvp;
out float v_ao;
void main() {
    v_ao = a_ao;
    gl_Position = u_mvp * vec4(a_position, 1.0);
}
"""

_G["vertex_colour_frag"] = """${header}
in float v_ao;
layout(location = 0) out vec4 o_colour;
void main() {
    o_colour = vec4(vec3(v_ao), 1.0);
}
"""

# --------------------------------------------------------------------------- WGSL compute (WebGPU)

# WGSL overrides only what differs from _T: its words, and the templates whose structure differs
# (entry points, resource declarations, helper functions, ternaries and boolean-vector mix() as
# select()). _G is not part of WGSL: the writer refuses, with one line, a pass that would need it,
# rather than emit GLSL into a WGSL file. Conventions: one bind group (0); ``r`` is a ``var``;
# ``nao_fetch`` is texelFetch on a 2-D array texture, ``nao_size`` its size.
_WGSL_WORDS: dict[str, str] = {
    "vec4": "vec4<f32>",
    "ivec2": "vec2<i32>",
    "ivec3": "vec3<i32>",
    "mat4": "mat4x4<f32>",
    "float": "f32",
    "int": "i32",
    "hvec4": "hvec4",
    "hmat4": "hmat4",
    "declare": "${kind}",
    "declare_typed": "${kind} ${name}: ${type}",
    "precise": "",
    "fetch": "nao_fetch",
    "lod": "",
    "size_of": "nao_size(${name})",
    "inc": "${name}++",
}

_W: dict[str, str] = {}

_W["header"] = "// WGSL (WebGPU compute), generated by neuralao from the same templates as the GLSL"
# WGSL: the product types as aliases; fp16 needs the device feature shader-f16 (a runner without it
# puts arithmetic_fp32 in place of arithmetic_fp16: the manifest's "arithmetic" gives both texts).
_W["arithmetic_fp32"] = """// conv products: fp32
alias hvec4 = vec4<f32>;
alias hmat4 = mat4x4<f32>;"""
_W["arithmetic_fp16"] = """// conv products: fp16 (device feature shader-f16), sums in fp32
enable f16;
alias hvec4 = vec4<f16>;
alias hmat4 = mat4x4<f16>;"""
_W["storage_format_rgba32f"] = "rgba32float"
_W["storage_format_rgba16f"] = "rgba16float"
_W["conv_block_acc_sep"] = "; var "  # one name per WGSL declaration

_W["prelude"] = """// Overflow-safe activations (exp() only sees arguments <= 0).
fn nao_tanh(x: vec4<f32>) -> vec4<f32> {
    let e = exp(-2.0 * abs(x));
    return sign(x) * ((1.0 - e) / (1.0 + e));
}

fn nao_sigmoid(x: vec4<f32>) -> vec4<f32> {
    let e = exp(-abs(x));
    let r = 1.0 / (1.0 + e);
    return select(e * r, r, x >= vec4<f32>(0.0));
}

fn nao_leaky_relu(x: vec4<f32>, alpha: f32) -> vec4<f32> {
    return select(alpha * x, x, x >= vec4<f32>(0.0));
}

fn nao_fetch(t: texture_2d_array<f32>, p: vec3<i32>) -> vec4<f32> {
    return textureLoad(t, p.xy, p.z, 0);
}

fn nao_size(t: texture_2d_array<f32>) -> vec2<i32> {
    return vec2<i32>(textureDimensions(t));
}"""

_W["act_Elu"] = "select(${alpha} * (exp(min(${x}, vec4<f32>(0.0))) - 1.0), ${x}, ${x} >= vec4<f32>(0.0))"
# WGSL's clamp() takes bounds of its argument's type.
_W["act_HardSigmoid"] = "clamp(${alpha} * ${x} + ${beta}, vec4<f32>(0.0), vec4<f32>(1.0))"
_W["act_HardSwish"] = "(${x} * clamp(0.16666667 * ${x} + 0.5, vec4<f32>(0.0), vec4<f32>(1.0)))"
_W["prelude_erf"] = """fn nao_erf(x: vec4<f32>) -> vec4<f32> {
    let z = abs(x);
    let t = 1.0 / (1.0 + 0.5 * z);
    let p = -z * z - 1.26551223 + t * (1.00002368 + t * (0.37409196 + t * (0.09678418 + t * (-0.18628806
        + t * (0.27886807 + t * (-1.13520398 + t * (1.48851587 + t * (-0.82215223 + t * 0.17087277))))))));
    let big = sign(x) * (1.0 - t * exp(p));
    let x2 = x * x;
    let small = 1.1283791671 * x * (1.0 + x2 * (-0.3333333333 + x2 * (0.1 + x2 * (-0.0238095238
        + x2 * (0.0046296296 + x2 * -0.0007575758)))));
    return select(big, small, z < vec4<f32>(0.5));
}"""

_W["compute_pass"] = """${header}
${arithmetic}
// neuralao compute pass ${pass_index}: ${summary}

${prelude}

${declarations}

@compute @workgroup_size(${local_x}, ${local_y}, 1)
fn main(@builtin(global_invocation_id) gid_u: vec3<u32>) {
    let gid = vec3<i32>(gid_u);
    let out_size = vec2<i32>(textureDimensions(dst));
    if (gid.x >= out_size.x || gid.y >= out_size.y || gid.z >= ${out_layers}) {
        return;
    }
${body}
${epilogue}
    textureStore(dst, ${store_xy}, gid.z, r);
}
"""

_W["sampler_array_decl"] = "@group(0) @binding(${binding}) var ${name}: texture_2d_array<f32>;"
_W["image_array_decl"] = "@group(0) @binding(${binding}) var dst: texture_storage_2d_array<${format}, write>;"
_W["params_decl"] = "@group(0) @binding(${binding}) var<storage, read> prm: array<vec4<f32>>;"
_W["uniform_int_decl"] = "@group(0) @binding(${slot}) var<uniform> ${name}: i32;"
_W["uniform_float_decl"] = "@group(0) @binding(${slot}) var<uniform> ${name}: f32;"
_W["size_decl"] = "    let ${size} = nao_size(${src});"

_W["compute_pass_block"] = """${header}
${arithmetic}
// neuralao compute pass ${pass_index}: ${summary}
// One invocation: ${block_x}x${block_y} output texels x ${block_layers} output layer(s) \
from layer ${block_layers} * gid.z.

${prelude}

${declarations}

// Zero padding without a branch: q is clamped into the input; returns 1 inside, 0 outside.
fn nao_clip(q: ptr<function, vec2<i32>>, size: vec2<i32>) -> f32 {
    let k = select(0.0, 1.0, all(*q >= vec2<i32>(0)) && all(*q < size));
    *q = clamp(*q, vec2<i32>(0), size - 1);
    return k;
}

fn nao_tap(o: i32) -> mat4x4<f32> {
    return mat4x4<f32>(prm[o], prm[o + 1], prm[o + 2], prm[o + 3]);
}

// Epilogue and store of output texel xy, layer z (skipped outside the output: partial blocks).
fn nao_store(xy: vec2<i32>, z: i32, acc: vec4<f32>) {
    if (all(xy < vec2<i32>(textureDimensions(dst)))) {
        var r = acc;
${epilogue}
        textureStore(dst, ${store_xy}, z, r);
    }
}

@compute @workgroup_size(${local_x}, ${local_y}, 1)
fn main(@builtin(global_invocation_id) gid_u: vec3<u32>) {
    let gid = vec3<i32>(gid_u);
    let base = gid.xy * vec2<i32>(${block_x}, ${block_y});
    let z0 = gid.z * ${block_layers};
    if (any(base >= vec2<i32>(textureDimensions(dst)))) {
        return;
    }
${body}
${stores}
}
"""
# WGSL has no inout: nao_clip takes q by pointer.
_W["conv_block_coord"] = (
    "            var q${p} = qb + vec2<i32>(${qx}, ${qy}); let k${p} = nao_clip(&q${p}, in_size);"
)

# WGSL has no ``precise``: the coordinates rely on nao_div's fma residual step alone.
_W["prelude_div"] = """fn nao_div(a: f32, b: f32) -> f32 {
    let q = a / b;
    let r = fma(-q, b, a);
    return q + r / b;
}"""
_W["coord_pytorch_half_pixel"] = "select(0.0, nao_div(${x} + 0.5, ${scale}) - 0.5, ${len_out} > 1.0)"
_W["coord_align_corners"] = (
    "select(0.0, nao_div(${x} * (${len_in} - 1.0), ${len_out} - 1.0), ${len_out} > 1.0)"
)
_W["coord_tf_crop_and_resize"] = (
    "select(0.5 * (${start} + ${end}) * (${len_in} - 1.0), "
    "${start} * (${len_in} - 1.0) + nao_div(${x} * (${end} - "
    "${start}) * (${len_in} - 1.0), ${len_out} - 1.0), ${len_out} > 1.0)"
)
_W["round_round_prefer_floor"] = "select(floor(${v}), ceil(${v}), fract(${v}) > 0.5)"
_W["round_round_prefer_ceil"] = "select(floor(${v}), ceil(${v}), fract(${v}) >= 0.5)"

_W["resize_inside"] = "    let outside = false;"
_W["prelude_cubic"] = """fn nao_cubic(t: f32, a: f32) -> f32 {
    let x = abs(t);
    if (x <= 1.0) {
        return ((a + 2.0) * x - (a + 3.0)) * x * x + 1.0;
    }
    if (x < 2.0) {
        return ((x - 5.0) * x + 8.0) * x * a - 4.0 * a;
    }
    return 0.0;
}"""

_W["binary_guard_div"] = (
    "    b = select(vec4<f32>(1.0), b, "
    "vec4<i32>(4 * gid.z) + vec4<i32>(0, 1, 2, 3) < vec4<i32>(${channels}));"
)

_W["pad_wrap"] = """    x = select(in_size.x - 1 - (-x - 1) % in_size.x, x % in_size.x, x >= 0);
    y = select(in_size.y - 1 - (-y - 1) % in_size.y, y % in_size.y, y >= 0);
    var r = nao_fetch(src0, vec3<i32>(x, y, gid.z));"""
_W["pad_reflect_body"] = """    let in_size = nao_size(src0);
    var x = select(2 * (in_size.x - 1) - gid.x, gid.x, gid.x < in_size.x);
    var y = select(2 * (in_size.y - 1) - gid.y, gid.y, gid.y < in_size.y);
    x = clamp(x, 0, in_size.x - 1);
    y = clamp(y, 0, in_size.y - 1);
    if (u_flip_y != 0) {
        y = in_size.y - 1 - y;  // source texture stored bottom-up
    }
    var r = nao_fetch(src0, vec3<i32>(x, y, gid.z));"""
_W["crop_body"] = """    let y = select(gid.y, out_size.y - 1 - gid.y, u_flip_y != 0);
    var r = nao_fetch(src0, vec3<i32>(gid.x, y, gid.z));"""

_W["epilogue_prelu"] = "    r = select(r * prm[${slope_offset} + ${z}], r, r >= vec4<f32>(0.0));"
_W["epilogue_rdiv"] = (
    "    r = prm[${offset} + ${z}] / select(vec4<f32>(1.0), r, vec4<i32>(4 * ${z}) + vec4<i32>(0, 1, 2, 3) < "
    "vec4<i32>(${channels}));"
)
_W["pick"] = "select(${b}, ${a}, ${cond})"
_W["pointwise_reflect_guard"] = (
    "select(vec4<f32>(0.0), nao_fetch(${src}, vec3<i32>(rx, ry, ${layer})), "
    "vec4<i32>(4 * ${layer}) + vec4<i32>(0, 1, 2, 3) < vec4<i32>(${channels}))"
)
_W["pointwise_array"] = "    var ${name}: array<vec4<f32>, ${n}>;"
_W["epilogue_guard_div"] = (
    "        b = select(vec4<f32>(1.0), b, "
    "vec4<i32>(4 * ${z}) + vec4<i32>(0, 1, 2, 3) < vec4<i32>(${channels}));"
)
_W["flip_xy"] = "vec2<i32>(${xy}.x, select(${xy}.y, ${size}.y - 1 - ${xy}.y, u_flip_y != 0))"
_W["dst_size"] = "vec2<i32>(textureDimensions(dst))"
_W["conv_read_reflect_guard"] = (
    "select(vec4<f32>(0.0), nao_fetch(${src}, vec3<i32>(rx, ry, l)), "
    "vec4<i32>(4 * l) + vec4<i32>(0, 1, 2, 3) < vec4<i32>(${channels}))"
)
_W["epilogue_guard"] = (
    "    r = select(vec4<f32>(0.0), r, vec4<i32>(4 * ${z}) + vec4<i32>(0, 1, 2, 3) < vec4<i32>(${channels}));"
)


# --------------------------------------------------------------------------- Vulkan GLSL (SPIR-V)

# The GLSL compute passes as Vulkan GLSL (glslangValidator -V): the GLSL table with these overrides.
# Every resource sits in descriptor set 0 at its own binding (inputs 0..n-1, output n, params n + 1,
# uniform block n + 2). Inputs are sampled images without a sampler (``texture2DArray``,
# GL_EXT_samplerless_texture_functions): the passes only texelFetch, so an engine binds no VkSampler,
# and naga's SPIR-V front end (wgpu) reads OpImageFetch on an image but not the OpImage that a
# combined ``sampler2DArray`` needs. Loose uniforms are not allowed in Vulkan GLSL: a pass's scalar
# (``u_flip_y``, a scalar graph input) is the one member of a std140 uniform block, at offset 0.
_V: dict[str, str] = {}
_V["header"] = """#version ${version}
#extension GL_EXT_samplerless_texture_functions : require"""
_V["sampler_array_decl"] = "layout(set = 0, binding = ${binding}) uniform highp texture2DArray ${name};"
_V["image_array_decl"] = (
    "layout(set = 0, binding = ${binding}, ${format}) writeonly uniform highp image2DArray dst;"
)
_V["params_decl"] = """layout(std430, set = 0, binding = ${binding}) readonly buffer Params {
    vec4 prm[];
};"""
_V["uniform_int_decl"] = """layout(std140, set = 0, binding = ${slot}) uniform PassUniforms {
    int ${name};
};"""
_V["uniform_float_decl"] = """layout(std140, set = 0, binding = ${slot}) uniform PassUniforms {
    float ${name};
};"""


# --------------------------------------------------------------------------- filling


class _WithWords(Template):
    """A template of ``_T`` / ``_G`` / ``_W``: a braced placeholder may also be ``${word:name}``."""

    braceidpattern = r"(?a:[_a-z][_a-z0-9]*(?::[_a-z][_a-z0-9]*)?)"


def _word(words: dict[str, str], ident: str) -> str | None:
    """The text of the dialect word ``ident`` (``word`` or ``word:name``) in ``words``; None when
    ``ident`` is a field that the writer fills."""
    word, named, name = ident.partition(":")
    kind, _, type_ = word.partition("_")
    if kind in ("let", "var") and type_ in _TYPES:
        form = words["declare_typed" if named else "declare"]
        return Template(form).substitute(kind=kind, type=words[type_], name=name)
    if word in words:
        text = Template(words[word])
        takes_name = "name" in text.get_identifiers()
        if takes_name != bool(named):
            raise KeyError(f"${{{ident}}}: dialect word {word!r} takes {'a' if takes_name else 'no'} name")
        return text.substitute(name=name)
    if named:
        raise KeyError(f"no dialect word {word!r} (in ${{{ident}}})")
    return None


def _with_words(texts: dict[str, str], words: dict[str, str]) -> dict[str, Template]:
    """``texts`` with the dialect's ``words`` put in, once, at import: what is left to fill is the
    writer's fields."""
    out = {}
    for name, text in texts.items():
        tpl = _WithWords(text)
        found = {i: w for i in tpl.get_identifiers() if (w := _word(words, i)) is not None}
        out[name] = Template(tpl.safe_substitute(found))
    return out


TEMPLATES: dict[str, Template] = _with_words({**_T, **_G}, _WORDS)
WGSL_TEMPLATES: dict[str, Template] = _with_words({**_T, **_W}, {**_WORDS, **_WGSL_WORDS})
VULKAN_TEMPLATES: dict[str, Template] = _with_words({**_T, **_G, **_V}, _WORDS)


def fill_from(templates: dict[str, Template], template: str, what: str, /, **fields: object) -> str:
    """Fill ``templates[template]``: every placeholder must be given and nothing else (strict, so a
    template and its caller cannot drift apart). Values are converted with ``str``; the caller formats
    floats (see ``neuralao.export.glsl.graph.glsl_float``). Shared by the generated shaders and the
    baselines'."""
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


def fill_wgsl(template: str, /, **fields: object) -> str:
    """Fill the WGSL template named ``template`` (a WGSL override, else the shared template in WGSL
    words); every placeholder must be given and nothing else."""
    return fill_from(WGSL_TEMPLATES, template, "WGSL", **fields)


def fill_vulkan(template: str, /, **fields: object) -> str:
    """Fill the Vulkan GLSL template named ``template`` (a Vulkan override, else the GLSL template);
    every placeholder must be given and nothing else."""
    return fill_from(VULKAN_TEMPLATES, template, "Vulkan GLSL", **fields)
