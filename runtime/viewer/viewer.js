// neuralao viewer: plain WebGL2 (and WebGPU for a screen-space U-Net, through wgsl.js), no dependencies.
// See runtime/viewer.py for the passes and the data.
"use strict";

(function () {
  const S = window.NEURALAO_SCENE;
  const canvas = document.getElementById("view");
  const status = document.getElementById("status");
  const params = new URLSearchParams(window.location.search);
  const W = parseInt(params.get("w") || S.size[0], 10);
  const H = parseInt(params.get("h") || S.size[1], 10);
  canvas.width = W;
  canvas.height = H;
  const gl = canvas.getContext("webgl2", { antialias: false, preserveDrawingBuffer: true });
  const api = { ready: false, error: null };
  window.neuralao = api;
  function fail(msg) {
    api.error = msg;
    status.textContent = "error: " + msg;
    throw new Error(msg);
  }
  if (!gl) fail("WebGL2 is not available");
  if (!gl.getExtension("EXT_color_buffer_float")) fail("EXT_color_buffer_float is not available (float targets)");

  // ------------------------------------------------------------------ small helpers
  function b64floats(s) {
    const bin = atob(s);
    const bytes = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
    return new Float32Array(bytes.buffer);
  }
  function b64bytes(f32) {
    const u8 = new Uint8Array(f32.buffer);
    let s = "";
    for (let i = 0; i < u8.length; i += 0x8000) s += String.fromCharCode.apply(null, u8.subarray(i, i + 0x8000));
    return btoa(s);
  }
  function compile(type, src, what) {
    const sh = gl.createShader(type);
    gl.shaderSource(sh, src);
    gl.compileShader(sh);
    if (!gl.getShaderParameter(sh, gl.COMPILE_STATUS)) fail(what + ": " + gl.getShaderInfoLog(sh));
    return sh;
  }
  function program(vs, fs, what) {
    const p = gl.createProgram();
    gl.attachShader(p, compile(gl.VERTEX_SHADER, vs, what + " (vertex)"));
    gl.attachShader(p, compile(gl.FRAGMENT_SHADER, fs, what + " (fragment)"));
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) fail(what + ": " + gl.getProgramInfoLog(p));
    return p;
  }
  function floatTarget(w, h) {
    const t = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, t);
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA32F, w, h);
    for (const k of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(gl.TEXTURE_2D, k, gl.NEAREST);
    return t;
  }
  // column-major 4x4 matrices
  function mul(a, b) {
    const o = new Float32Array(16);
    for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) {
      let s = 0;
      for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
      o[c * 4 + r] = s;
    }
    return o;
  }
  function perspective(fovy, aspect, near, far) {
    const f = 1 / Math.tan(fovy / 2), o = new Float32Array(16);
    o[0] = f / aspect; o[5] = f; o[10] = (far + near) / (near - far); o[11] = -1; o[14] = 2 * far * near / (near - far);
    return o;
  }
  function lookAt(eye, at, up) {
    const z = norm(sub(eye, at)), x = norm(cross(up, z)), y = cross(z, x);
    return new Float32Array([x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0,
      -dot(x, eye), -dot(y, eye), -dot(z, eye), 1]);
  }
  const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const norm = (a) => { const l = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / l, a[1] / l, a[2] / l]; };

  // ------------------------------------------------------------------ fixed programs
  const GBUFFER_VS = `#version 300 es
precision highp float;
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in float a_ao;
layout(location = 3) in vec2 a_uv;
layout(location = 4) in vec2 a_uv_base;
uniform mat4 u_mvp;
out vec3 v_position; out vec3 v_normal; out float v_ao; out vec2 v_uv; out vec2 v_uv_base;
void main() {
  v_position = a_position; v_normal = a_normal; v_ao = a_ao; v_uv = a_uv; v_uv_base = a_uv_base;
  gl_Position = u_mvp * vec4(a_position, 1.0);
}`;
  const GBUFFER_FS = `#version 300 es
precision highp float;
precision highp sampler2D;
in vec3 v_position; in vec3 v_normal; in float v_ao; in vec2 v_uv; in vec2 v_uv_base;
uniform int u_mode;            // 0: vertex AO, 1: texture AO (red channel), 2: none (a shader pass follows)
uniform sampler2D u_occlusion;
uniform sampler2D u_base;      // scene bakes: base colour texture (sRGB texture: sampled as linear), else white
uniform vec4 u_factor;         // scene bakes: baseColorFactor (linear), else white
layout(location = 0) out vec4 o_position;
layout(location = 1) out vec4 o_normal;
layout(location = 2) out vec4 o_ao;
layout(location = 3) out vec4 o_albedo;
void main() {
  vec3 n = normalize(v_normal);
  if (!gl_FrontFacing) n = -n;   // viewer-facing, as pipeline/gbuffers/rasterizer.py
  o_position = vec4(v_position, 1.0);
  o_normal = vec4(n, 1.0);
  float ao = u_mode == 0 ? v_ao : (u_mode == 1 ? texture(u_occlusion, v_uv).r : 1.0);
  o_ao = vec4(ao, 0.0, 0.0, 1.0);
  o_albedo = u_factor * texture(u_base, v_uv_base);
}`;
  // The screen-space U-Net's G-buffer, as pipeline/gbuffers/rasterizer.py writes it: camera-space
  // position (-z = linear depth; w = 1 on the foreground, 0 on background) and the camera-space normal
  // (the viewer-facing object-space normal rotated by the view matrix, renormalised).
  const CAMERA_VS = `#version 300 es
precision highp float;
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
uniform mat4 u_mvp;
uniform mat4 u_view;
out vec3 v_cam; out vec3 v_normal;
void main() {
  v_cam = (u_view * vec4(a_position, 1.0)).xyz; v_normal = a_normal;
  gl_Position = u_mvp * vec4(a_position, 1.0);
}`;
  const CAMERA_FS = `#version 300 es
precision highp float;
in vec3 v_cam; in vec3 v_normal;
uniform mat3 u_rotation;       // world -> camera rotation (the view matrix's)
layout(location = 0) out vec4 o_position;
layout(location = 1) out vec4 o_normal;
void main() {
  vec3 n = normalize(v_normal);
  if (!gl_FrontFacing) n = -n;
  o_position = vec4(v_cam, 1.0);
  o_normal = vec4(normalize(u_rotation * n), 1.0);
}`;
  const FULLSCREEN_VS = `#version 300 es
void main() {
  vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
  gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}`;
  const DISPLAY_FS = `#version 300 es
precision highp float;
precision highp sampler2D;
uniform sampler2D u_ao;
uniform sampler2D u_position;
uniform sampler2D u_albedo;
uniform int u_colour;          // 1: base colour x AO (scene bakes, linear -> sRGB); 0: AO as grey
out vec4 o_colour;
void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  float mask = texelFetch(u_position, p, 0).w;
  float ao = clamp(texelFetch(u_ao, p, 0).r, 0.0, 1.0);
  // AO written to the display as is (as AO maps are viewed: 0.5 shows as mid grey); background dark
  vec3 shade = u_colour == 1 ? pow(texelFetch(u_albedo, p, 0).rgb * ao, vec3(1.0 / 2.2)) : vec3(ao);
  vec3 c = mask >= 0.5 ? shade : vec3(0.114, 0.122, 0.137);
  o_colour = vec4(c, 1.0);
}`;
  const gbufferProg = program(GBUFFER_VS, GBUFFER_FS, "G-buffer");
  const displayProg = program(FULLSCREEN_VS, DISPLAY_FS, "display");
  const cameraProg = program(CAMERA_VS, CAMERA_FS, "camera-space G-buffer");
  const emptyVAO = gl.createVertexArray();

  // ------------------------------------------------------------------ targets
  const tPosition = floatTarget(W, H), tNormal = floatTarget(W, H), tBaked = floatTarget(W, H), tShader = floatTarget(W, H);
  const tAlbedo = floatTarget(W, H);
  const depth = gl.createRenderbuffer();
  gl.bindRenderbuffer(gl.RENDERBUFFER, depth);
  gl.renderbufferStorage(gl.RENDERBUFFER, gl.DEPTH_COMPONENT32F, W, H);
  const fbGbuffer = gl.createFramebuffer();
  gl.bindFramebuffer(gl.FRAMEBUFFER, fbGbuffer);
  [tPosition, tNormal, tBaked, tAlbedo].forEach((t, i) => gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0 + i, gl.TEXTURE_2D, t, 0));
  gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.DEPTH_ATTACHMENT, gl.RENDERBUFFER, depth);
  gl.drawBuffers([gl.COLOR_ATTACHMENT0, gl.COLOR_ATTACHMENT1, gl.COLOR_ATTACHMENT2, gl.COLOR_ATTACHMENT3]);
  if (gl.checkFramebufferStatus(gl.FRAMEBUFFER) !== gl.FRAMEBUFFER_COMPLETE) fail("G-buffer framebuffer incomplete");
  const fbShader = gl.createFramebuffer();
  gl.bindFramebuffer(gl.FRAMEBUFFER, fbShader);
  gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, tShader, 0);
  if (gl.checkFramebufferStatus(gl.FRAMEBUFFER) !== gl.FRAMEBUFFER_COMPLETE) fail("AO framebuffer incomplete");
  const tCamPosition = floatTarget(W, H), tCamNormal = floatTarget(W, H);
  const fbCamera = gl.createFramebuffer();
  gl.bindFramebuffer(gl.FRAMEBUFFER, fbCamera);
  [tCamPosition, tCamNormal].forEach((t, i) =>
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0 + i, gl.TEXTURE_2D, t, 0));
  gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.DEPTH_ATTACHMENT, gl.RENDERBUFFER, depth);
  gl.drawBuffers([gl.COLOR_ATTACHMENT0, gl.COLOR_ATTACHMENT1]);
  if (gl.checkFramebufferStatus(gl.FRAMEBUFFER) !== gl.FRAMEBUFFER_COMPLETE) {
    fail("camera G-buffer framebuffer incomplete");
  }
  // the screen-space U-Net's latest AO (one float per pixel, GL row order), shown by the display pass
  const tNetwork = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_2D, tNetwork);
  gl.texStorage2D(gl.TEXTURE_2D, 1, gl.R32F, W, H);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
  gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, 0, W, H, gl.RED, gl.FLOAT, new Float32Array(W * H).fill(1));

  // ------------------------------------------------------------------ screen-space U-Net (WebGPU)
  // A method with a `network` runs a U-Net export's whole frame in WebGPU (wgsl.js runFrame), as an
  // engine would: the page's camera-space G-buffer gives the frame's two inputs (linear depth -z, the
  // camera-space normal), the camera gives FrameUniforms (projection, AO radius, u_flip_y = 0: WebGPU's
  // row 0 is the top row), and the export's passes do the rest in the order of manifest.frame.steps
  // (a hybrid's GTAO and its blur, point sampling to the internal height, the model's input contract,
  // the network, upsampling with the hybrid's correction), as runtime/frame_runner.py does through wgpu.
  // WebGPU is asynchronous: a frame shows the latest finished AO; while one run is in flight, newer
  // frames coalesce into one more run.
  const net = { device: null, state: "none", error: null, busy: null, dirty: false, last: null };
  net.note = () => net.error ? " (error: " + net.error + ")" : net.state === "ready" ? ""
    : net.state === "pending" ? " (starting WebGPU...)" : " (" + net.state + ")";
  function networkOf(n) {
    return { program: { manifest: n.manifest, sources: n.sources, weights: b64floats(n.weights).buffer },
      radius: n.radius, model: n.model };
  }
  async function startWebGPU() {
    net.state = "pending";
    const unavailable = (why) => {
      net.state = "WebGPU is not available here (" + why + "): the U-Net is not shown; "
        + "the other methods run on WebGL2";
      document.getElementById("note").textContent = net.state;
      return null;
    };
    if (!navigator.gpu) {
      return unavailable("no navigator.gpu: it needs a WebGPU browser and file:// or http://127.0.0.1");
    }
    const adapter = await navigator.gpu.requestAdapter();
    if (!adapter) return unavailable("no adapter");
    const device = await adapter.requestDevice();
    device.addEventListener("uncapturederror", (e) => { net.error = e.error.message; });
    const info = adapter.info || {};
    net.adapter = [info.vendor, info.architecture, info.description].filter(Boolean).join(" ");
    net.device = device;
    net.state = "ready";
    return device;
  }
  function drawCameraGbuffer(m) {
    const v = view();
    gl.bindFramebuffer(gl.FRAMEBUFFER, fbCamera);
    gl.clearBufferfv(gl.COLOR, 0, new Float32Array([0, 0, 0, 0]));
    gl.clearBufferfv(gl.COLOR, 1, new Float32Array([0, 0, 0, 0]));
    gl.clearBufferfi(gl.DEPTH_STENCIL, 0, 1.0, 0);
    gl.enable(gl.DEPTH_TEST);
    gl.useProgram(cameraProg);
    gl.uniformMatrix4fv(gl.getUniformLocation(cameraProg, "u_mvp"), false, mvp());
    gl.uniformMatrix4fv(gl.getUniformLocation(cameraProg, "u_view"), false, v.matrix);
    const r = v.matrix;  // column-major: the upper 3x3 is the rotation
    gl.uniformMatrix3fv(gl.getUniformLocation(cameraProg, "u_rotation"), false,
      new Float32Array([r[0], r[1], r[2], r[4], r[5], r[6], r[8], r[9], r[10]]));
    gl.bindVertexArray(m.vao);
    gl.drawArrays(gl.TRIANGLES, 0, m.count);
  }
  // one run at a time; the G-buffer is read when the run starts (that frame's), the AO shown when it ends
  function requestNetwork(m) {
    if (!net.device) return;
    if (net.busy) { net.dirty = true; return; }
    const gb = { position: readTexture(tCamPosition), normal: readTexture(tCamNormal) };
    net.busy = runNetwork(m.network, gb).then((r) => {
      net.last = r;
      gl.bindTexture(gl.TEXTURE_2D, tNetwork);
      gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, 0, W, H, gl.RED, gl.FLOAT, r.ao);
    }, (e) => { net.error = String(e && e.message || e); }).then(() => {
      net.busy = null;
      if (methods[current] !== m) return;
      if (net.dirty) { net.dirty = false; render(); } else display(m, tNetwork);
    });
  }
  // gb: {position, normal} RGBA float32 W x H, GL rows (bottom first). The frame's inputs, top row first:
  // depth (H, W) -z on the foreground (position w = 1), 0 on background; normal (H, W, 4) xyz, w 0.
  function frameInputs(gb) {
    const depth = new Float32Array(W * H), normal = new Float32Array(4 * W * H);
    for (let r = 0; r < H; r++) {
      for (let c = 0; c < W; c++) {
        const src = (H - 1 - r) * W + c, dst = r * W + c;
        if (!(gb.position[4 * src + 3] >= 0.5)) continue;
        depth[dst] = -gb.position[4 * src + 2];
        for (let k = 0; k < 3; k++) normal[4 * dst + k] = gb.normal[4 * src + k];
      }
    }
    return { depth, normal };
  }
  // Returns {ao (W x H, GL rows), internal [w, h], ms, gbuffer}.
  async function runNetwork(n, gb) {
    const t0 = performance.now();
    const { depth, normal } = frameInputs(gb);
    const r = await neuralaoWgsl.runFrame(net.device, n.program, depth, normal, W, H,
      { yfov: YFOV, radius: n.radius }, false);
    const ao = new Float32Array(W * H);  // back to GL rows for the display texture
    for (let row = 0; row < H; row++) ao.set(r.ao.subarray((H - 1 - row) * W, (H - row) * W), row * W);
    return { ao: ao, internal: r.internal, ms: performance.now() - t0, gbuffer: gb };
  }

  // ------------------------------------------------------------------ methods
  function attribute(loc, data, size) {
    const b = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, b);
    gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
    gl.enableVertexAttribArray(loc);
    gl.vertexAttribPointer(loc, size, gl.FLOAT, false, 0, 0);
  }
  function buffer(data) {
    const b = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, b);
    gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
    return b;
  }
  function bindBuffer(loc, b, size) {
    gl.bindBuffer(gl.ARRAY_BUFFER, b);
    gl.enableVertexAttribArray(loc);
    gl.vertexAttribPointer(loc, size, gl.FLOAT, false, 0, 0);
  }
  const white = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_2D, white);
  gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA8, 1, 1, 0, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array([255, 255, 255, 255]));
  const WHITE = new Float32Array([1, 1, 1, 1]);
  // one copy of each mesh, shared by the methods drawn on it
  const geometries = S.geometries.map((g) => ({ count: g.count, positions: buffer(b64floats(g.positions)), normals: buffer(b64floats(g.normals)) }));
  let pending = 0;
  const methods = S.methods.map((m) => {
    const g = geometries[m.geometry];
    m.count = g.count;
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    bindBuffer(0, g.positions, 3);
    bindBuffer(1, g.normals, 3);
    if (m.ao) attribute(2, b64floats(m.ao), 1); else gl.vertexAttrib1f(2, 1.0);
    if (m.uv) attribute(3, b64floats(m.uv), 2); else gl.vertexAttrib2f(3, 0.0, 0.0);
    if (m.uv_base) attribute(4, b64floats(m.uv_base), 2); else gl.vertexAttrib2f(4, 0.0, 0.0);
    gl.bindVertexArray(null);
    const out = { name: m.name, kind: m.kind, count: m.count, vao: vao };
    if (m.network) out.network = networkOf(m.network);
    if (m.texture) out.texture = occlusionTexture(m.texture, m.name);
    if (m.parts) {  // scene bakes: one draw per primitive with its own material
      out.parts = m.parts.map((p) => ({ first: p.first, count: p.count, factor: new Float32Array(p.factor),
        occlusion: p.occlusion ? occlusionTexture(p.occlusion, m.name) : null,
        base: p.base ? colourTexture(p.base, m.name) : white }));
    }
    if (m.shader) {
      out.prog = program(m.shader.vertex, m.shader.fragment, "generated shader of " + m.name);
      out.inputs = m.shader.inputs;
      out.blocks = m.shader.blocks.map((b) => {
        const buf = gl.createBuffer();
        gl.bindBuffer(gl.UNIFORM_BUFFER, buf);
        gl.bufferData(gl.UNIFORM_BUFFER, b64floats(b.data), gl.STATIC_DRAW);
        const index = gl.getUniformBlockIndex(out.prog, b.name);
        if (index !== gl.INVALID_INDEX) gl.uniformBlockBinding(out.prog, index, b.binding);
        return { binding: b.binding, buffer: buf };
      });
    }
    return out;
  });
  // glTF: UV (0, 0) is the image's top-left texel, the first row uploaded (no flip); LINEAR, CLAMP_TO_EDGE.
  function occlusionTexture(uri, what) {
    const t = gl.createTexture();
    pending++;
    const img = new Image();
    img.onload = () => {
      gl.bindTexture(gl.TEXTURE_2D, t);
      gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, false);
      gl.texImage2D(gl.TEXTURE_2D, 0, gl.R8, img.width, img.height, 0, gl.RED, gl.UNSIGNED_BYTE, decodeRed(img));
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
      if (--pending === 0) start();
    };
    img.onerror = () => fail("cannot decode an occlusion texture of " + what);
    img.src = uri;
    return t;
  }
  // base colour: sRGB-encoded, sampled as linear (SRGB8_ALPHA8), repeating as glTF's default sampler
  function colourTexture(uri, what) {
    const t = gl.createTexture();
    pending++;
    const img = new Image();
    img.onload = () => {
      gl.bindTexture(gl.TEXTURE_2D, t);
      gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, false);
      gl.texImage2D(gl.TEXTURE_2D, 0, gl.SRGB8_ALPHA8, gl.RGBA, gl.UNSIGNED_BYTE, img);
      gl.generateMipmap(gl.TEXTURE_2D);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR_MIPMAP_LINEAR);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
      if (--pending === 0) start();
    };
    img.onerror = () => fail("cannot decode a base colour texture of " + what);
    img.src = uri;
    return t;
  }
  // exact 8-bit texel values, whatever the browser's colour management: read the PNG through a 2D canvas
  function decodeRed(img) {
    const c = document.createElement("canvas");
    c.width = img.width; c.height = img.height;
    const ctx = c.getContext("2d", { colorSpace: "srgb", willReadFrequently: true });
    ctx.drawImage(img, 0, 0);
    const rgba = ctx.getImageData(0, 0, img.width, img.height).data;
    const red = new Uint8Array(img.width * img.height);
    for (let i = 0; i < red.length; i++) red[i] = rgba[4 * i];
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    return red;
  }

  // ------------------------------------------------------------------ camera
  const lo = S.bounds[0], hi = S.bounds[1];
  const centre = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2];
  const diag = Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) || 1;
  const pose = { azimuth: 30, elevation: 20, distance: 1.6 };  // degrees, degrees, diagonals
  let current = 0;
  const YFOV = 45 * (Math.PI / 180);  // vertical field of view (radians), as Python's math.radians(45)
  function view() {
    const az = pose.azimuth * Math.PI / 180, el = pose.elevation * Math.PI / 180, r = pose.distance * diag;
    const eye = [centre[0] + r * Math.cos(el) * Math.sin(az), centre[1] + r * Math.sin(el), centre[2] + r * Math.cos(el) * Math.cos(az)];
    const near = Math.max(r - diag, r * 0.01), far = r + diag;
    return { eye: eye, matrix: lookAt(eye, centre, [0, 1, 0]), near: near, far: far };
  }
  function mvp() {
    const v = view();
    return mul(perspective(YFOV, W / H, v.near, v.far), v.matrix);
  }

  // ------------------------------------------------------------------ frame
  function render() {
    const m = methods[current];
    gl.viewport(0, 0, W, H);
    gl.bindFramebuffer(gl.FRAMEBUFFER, fbGbuffer);
    gl.clearBufferfv(gl.COLOR, 0, new Float32Array([0, 0, 0, 0]));
    gl.clearBufferfv(gl.COLOR, 1, new Float32Array([0, 0, 0, 0]));
    gl.clearBufferfv(gl.COLOR, 2, new Float32Array([1, 0, 0, 0]));
    gl.clearBufferfv(gl.COLOR, 3, new Float32Array([1, 1, 1, 1]));
    gl.clearBufferfi(gl.DEPTH_STENCIL, 0, 1.0, 0);
    gl.enable(gl.DEPTH_TEST);
    gl.disable(gl.CULL_FACE);
    gl.useProgram(gbufferProg);
    gl.uniformMatrix4fv(gl.getUniformLocation(gbufferProg, "u_mvp"), false, mvp());
    gl.uniform1i(gl.getUniformLocation(gbufferProg, "u_occlusion"), 0);
    gl.uniform1i(gl.getUniformLocation(gbufferProg, "u_base"), 1);
    gl.bindVertexArray(m.vao);
    const parts = m.parts || [{ first: 0, count: m.count, factor: WHITE, occlusion: m.texture || null, base: white }];
    for (const p of parts) {
      const mode = m.kind === "vertex" ? 0 : m.kind === "texture" ? 1 : m.kind === "scene" ? (p.occlusion ? 1 : 0) : 2;
      gl.uniform1i(gl.getUniformLocation(gbufferProg, "u_mode"), mode);
      gl.uniform4fv(gl.getUniformLocation(gbufferProg, "u_factor"), p.factor);
      gl.activeTexture(gl.TEXTURE0);
      gl.bindTexture(gl.TEXTURE_2D, p.occlusion);
      gl.activeTexture(gl.TEXTURE1);
      gl.bindTexture(gl.TEXTURE_2D, p.base);
      gl.drawArrays(gl.TRIANGLES, p.first, p.count);
    }
    let aoTex = tBaked;
    if (m.network) {  // the camera-space G-buffer, then the network on it (asynchronous, WebGPU)
      drawCameraGbuffer(m);
      requestNetwork(m);
      aoTex = tNetwork;
    }
    gl.disable(gl.DEPTH_TEST);
    if (m.prog) {  // the generated pass, unchanged, over the G-buffer
      gl.bindFramebuffer(gl.FRAMEBUFFER, fbShader);
      gl.useProgram(m.prog);
      for (const i of m.inputs) {
        gl.activeTexture(gl.TEXTURE0 + i.unit);
        gl.bindTexture(gl.TEXTURE_2D, i.source === "position" ? tPosition : tNormal);
        gl.uniform1i(gl.getUniformLocation(m.prog, i.sampler), i.unit);
      }
      for (const b of m.blocks) gl.bindBufferBase(gl.UNIFORM_BUFFER, b.binding, b.buffer);
      gl.bindVertexArray(emptyVAO);
      gl.drawArrays(gl.TRIANGLES, 0, 3);
      aoTex = tShader;
    }
    display(m, aoTex);
    return aoTex;
  }
  function display(m, aoTex) {
    gl.viewport(0, 0, W, H);
    gl.disable(gl.DEPTH_TEST);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.useProgram(displayProg);
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D, aoTex);
    gl.uniform1i(gl.getUniformLocation(displayProg, "u_ao"), 0);
    gl.activeTexture(gl.TEXTURE1);
    gl.bindTexture(gl.TEXTURE_2D, tPosition);
    gl.uniform1i(gl.getUniformLocation(displayProg, "u_position"), 1);
    gl.activeTexture(gl.TEXTURE2);
    gl.bindTexture(gl.TEXTURE_2D, tAlbedo);
    gl.uniform1i(gl.getUniformLocation(displayProg, "u_albedo"), 2);
    gl.uniform1i(gl.getUniformLocation(displayProg, "u_colour"), m.kind === "scene" ? 1 : 0);
    gl.bindVertexArray(emptyVAO);
    gl.drawArrays(gl.TRIANGLES, 0, 3);
    gl.bindVertexArray(null);
    status.textContent = m.name + (m.network ? net.note() : "");
  }
  function readTexture(tex) {
    const fb = gl.createFramebuffer();
    gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, tex, 0);
    const out = new Float32Array(W * H * 4);
    gl.readPixels(0, 0, W, H, gl.RGBA, gl.FLOAT, out);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.deleteFramebuffer(fb);
    return out;
  }

  // ------------------------------------------------------------------ UI
  const select = document.getElementById("method");
  methods.forEach((m, i) => { const o = document.createElement("option"); o.value = i; o.textContent = (i + 1) + ". " + m.name; select.appendChild(o); });
  select.onchange = () => { current = parseInt(select.value, 10); render(); };
  let drag = null;
  canvas.addEventListener("mousedown", (e) => { drag = [e.clientX, e.clientY]; });
  window.addEventListener("mouseup", () => { drag = null; });
  window.addEventListener("mousemove", (e) => {
    if (!drag) return;
    pose.azimuth -= (e.clientX - drag[0]) * 0.4;
    pose.elevation = Math.max(-89, Math.min(89, pose.elevation + (e.clientY - drag[1]) * 0.4));
    drag = [e.clientX, e.clientY];
    render();
  });
  canvas.addEventListener("wheel", (e) => { e.preventDefault(); pose.distance = Math.max(0.3, Math.min(10, pose.distance * Math.exp(e.deltaY * 0.001))); render(); }, { passive: false });
  window.addEventListener("keydown", (e) => {
    const k = parseInt(e.key, 10);
    if (k >= 1 && k <= methods.length) { current = k - 1; select.value = current; render(); }
  });

  // ------------------------------------------------------------------ test API
  api.methods = methods.map((m) => ({ name: m.name, kind: m.kind }));
  api.size = [W, H];
  api.setPose = (azimuth, elevation, distance) => { pose.azimuth = azimuth; pose.elevation = elevation; pose.distance = distance; render(); };
  api.setMethod = (i) => { current = i; select.value = i; render(); };
  api.capture = () => {
    const aoTex = render();
    gl.finish();
    const dbg = gl.getExtension("WEBGL_debug_renderer_info");
    const renderer = dbg ? gl.getParameter(dbg.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);
    return { width: W, height: H, method: methods[current].name, renderer: renderer,
      position: b64bytes(readTexture(tPosition)), normal: b64bytes(readTexture(tNormal)), ao: b64bytes(readTexture(aoTex)),
      albedo: b64bytes(readTexture(tAlbedo)) };
  };
  // The U-Net on the current pose: resolves to the camera-space G-buffer the run read and its AO (bottom
  // row first, base64 float32), once WebGPU has started; rejects where WebGPU is absent.
  api.captureNetwork = async () => {
    await api.webgpu;
    if (!net.device) throw new Error(net.state);
    const m = methods[current];
    if (!m.network) throw new Error(m.name + " is not a screen-space method");
    while (net.busy) await net.busy;
    render();
    await net.busy;
    if (net.error) throw new Error(net.error);
    const r = net.last;
    return { width: W, height: H, method: m.name, model: m.network.model, radius: m.network.radius,
      yfov: YFOV, internal: r.internal, ms: r.ms, adapter: net.adapter,
      position: b64bytes(r.gbuffer.position), normal: b64bytes(r.gbuffer.normal), ao: b64bytes(r.ao) };
  };
  // a texture of the current U-Net's latest frame (e.g. "gtao"): base64 float32 (layers, h, w, lanes), the
  // rows as WebGPU stores them (row 0 at the top)
  api.readNetworkTexture = async (id) => {
    while (net.busy) await net.busy;
    return b64bytes(await neuralaoWgsl.readFrame(net.device, methods[current].network.program, id));
  };
  api.webgpu = !methods.some((m) => m.network) ? Promise.resolve()
    : startWebGPU().catch((e) => { net.state = "WebGPU failed: " + e; });
  api.webgpu.then(() => { if (api.ready && methods[current].network) render(); });
  function start() { render(); api.ready = true; }
  if (pending === 0) start();
})();
