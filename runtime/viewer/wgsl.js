// neuralao WGSL runner for the browser (WebGPU): the JavaScript twin of runtime/wgsl_runner.py (the
// network's passes) and runtime/frame_runner.py (a U-Net's whole frame). Runs a `neuralao-wgsl-compute`
// export (manifest, .wgsl sources, weights.bin) exactly as its manifest says: textures at their size
// formulas, one bind group per pass, the passes in one compute pass encoder. No dependencies.
//
//   const out = await neuralaoWgsl.run(device, program, x, width, height, scalars, flipY);
//     the network's passes alone, on its input tensor:
//     program : {manifest, sources: {file name: WGSL text}, weights: ArrayBuffer}
//     x       : Float32Array (C, H, W) of the input, C = manifest.input.channels, row 0 = the top row
//     scalars : {onnx input name: number} for the manifest's uniforms (e.g. {radius: rho})
//     returns Float32Array (C_out, H, W) of the first output
//
//   const r = await neuralaoWgsl.runFrame(device, program, depth, normal, width, height, camera, flipY);
//     a U-Net export with frame passes (manifest.frame): the engine's two inputs in, the AO out, every
//     step of manifest.frame.steps in between (GTAO, resampling, the network, upsampling, composite):
//     depth   : Float32Array (H, W), linear depth -z_cam in scene units, 0 on background
//     normal  : Float32Array (H, W, 4), camera-space unit normal (xyz, OpenGL axes), zeros on background
//     camera  : {yfov (radians), radius (the AO radius in scene units)}
//     flipY   : false: row 0 of every array is the top row (WebGPU's texture origin); true: bottom-up
//     returns {ao: Float32Array (H, W) in [0, 1], 1 on background, in the inputs' row order,
//              internal: [w, h] of the network's input}
//
//   const texels = await neuralaoWgsl.readFrame(device, program, id);
//     any texture of the latest runFrame (e.g. "gtao"): Float32Array (layers, h, w, lanes), texture rows
//
// The pipelines and the weights buffer are made once per (device, program) and the textures, bind
// groups and read-back buffers once per frame size, so a viewer that runs every frame compiles nothing
// after its first frame. Calls on one program must not overlap (await each).
"use strict";

(function () {
  const FORMATS = { RGBA32F: "rgba32float", RGBA16F: "rgba16float", R32F: "r32float" };
  const TEXEL_BYTES = { rgba32float: 16, rgba16float: 8, r32float: 4 };
  const FRAME_UNIFORM_BYTES = 32;  // FrameUniforms: u_proj@0, u_radius@8, u_pixels_per_unit@12, u_flip_y@16

  // ------------------------------------------------------------------ sizes
  // a network texture's size, {of, num, den, offset} of the network's own sizes
  function size(dim, sizes) {
    const v = sizes[dim.of] * dim.num;
    if (v % dim.den) throw new Error(`texture size ${dim.formula} is fractional for ${dim.of} = ${sizes[dim.of]}`);
    return v / dim.den + dim.offset;
  }
  // a frame texture's size formula (`W`, `w*1/8`, `hp*1/2+1`, `1`), as export/glsl/frame.py _eval
  function frameSize(formula, sym) {
    const m = /^(?:(\w+)(?:\*(\d+)\/(\d+))?)?([+-]?\d+)?$/.exec(String(formula));
    if (!m || !(m[1] || m[4])) throw new Error(`size formula ${formula} is not symbol[*num/den][+-offset]`);
    if (m[1] && /^\d+$/.test(m[1])) return parseInt(m[1], 10);
    const value = m[1] ? Math.floor(sym[m[1]] * parseInt(m[2] || "1", 10) / parseInt(m[3] || "1", 10)) : 0;
    return value + parseInt(m[4] || "0", 10);
  }
  // Python's round(): halves to even (export/glsl/frame.py frame_sizes)
  function roundHalfEven(v) {
    const f = Math.floor(v), d = v - f;
    return d > 0.5 ? f + 1 : d < 0.5 ? f : (f % 2 === 0 ? f : f + 1);
  }
  // {texture id: {w, h, layers, format}} of a frame, as export/glsl/frame.py frame_sizes
  function frameSizes(m, width, height) {
    const ih = m.frame.internal_height;
    const [w, h] = ih ? [Math.max(1, roundHalfEven(width * ih / height)), ih] : [width, height];
    const p = m.pad.multiple;
    if (Math.min(w, h) < p) throw new Error(`the network's input ${w}x${h} is smaller than the pad multiple ${p}`);
    const sym = { W: width, H: height, w, h, wp: Math.ceil(w / p) * p, hp: Math.ceil(h / p) * p };
    const out = {};
    for (const [id, t] of Object.entries(m.frame.textures)) {
      out[id] = { w: frameSize(t.width, sym), h: frameSize(t.height, sym), layers: t.layers, format: FORMATS[t.format] };
    }
    return out;
  }
  // the steps that run at this size, as export/glsl/frame.py active_steps
  function activeSteps(m, sizes, width, height) {
    const low = sizes[m.input.texture], same = low.w === width && low.h === height;
    return m.frame.steps.filter((s) => !("skip" in s) && (!("when" in s) || (s.when === "(w, h) == (W, H)") === same));
  }

  // ------------------------------------------------------------------ resources
  function weightsBuffer(device, bytes) {
    const buf = device.createBuffer({ size: Math.max(16, Math.ceil(bytes.byteLength / 4) * 4),
      usage: GPUBufferUsage.STORAGE, mappedAtCreation: true });
    new Uint8Array(buf.getMappedRange()).set(new Uint8Array(bytes));
    buf.unmap();
    return buf;
  }
  function uniformBuffer(device, bytes) {
    return device.createBuffer({ size: bytes, usage: GPUBufferUsage.UNIFORM | GPUBufferUsage.COPY_DST });
  }
  function texture(device, w, h, layers, format) {
    const U = GPUTextureUsage;
    const t = device.createTexture({ size: [w, h, layers], format, dimension: "2d",
      usage: U.TEXTURE_BINDING | U.STORAGE_BINDING | U.COPY_DST | U.COPY_SRC });
    return { texture: t, view: t.createView({ dimension: "2d-array" }), w, h, layers, format };
  }
  // A pass's pipeline: its inputs (unfilterable-float 2d arrays), its output (a write-only storage
  // texture of `format`), its weights range and its uniform buffers (`uniformBindings`), in group 0.
  function pipelineOf(device, program, ps, format, uniformBindings) {
    const C = GPUShaderStage.COMPUTE, layout = [];
    for (const inp of ps.inputs) {
      layout.push({ binding: inp.binding, visibility: C,
        texture: { sampleType: "unfilterable-float", viewDimension: "2d-array" } });
    }
    layout.push({ binding: ps.output.binding, visibility: C,
      storageTexture: { access: "write-only", format, viewDimension: "2d-array" } });
    if (ps.params) layout.push({ binding: ps.params.binding, visibility: C, buffer: { type: "read-only-storage" } });
    for (const b of uniformBindings) layout.push({ binding: b, visibility: C, buffer: { type: "uniform" } });
    const bgl = device.createBindGroupLayout({ entries: layout });
    const module = device.createShaderModule({ code: program.sources[ps.shader] });
    const pipeline = device.createComputePipeline({
      layout: device.createPipelineLayout({ bindGroupLayouts: [bgl] }),
      compute: { module, entryPoint: "main" },
    });
    return { bgl, pipeline };
  }
  // the bind group of a pass: `tex` by id, `uniforms` [{binding, buffer}]
  function bindGroupOf(device, ps, bgl, tex, weights, uniforms) {
    const group = ps.inputs.map((inp) => ({ binding: inp.binding, resource: tex[inp.texture].view }));
    group.push({ binding: ps.output.binding, resource: tex[ps.output.texture].view });
    if (ps.params) {
      group.push({ binding: ps.params.binding,
        resource: { buffer: weights, offset: ps.params.offset, size: ps.params.bytes } });
    }
    for (const u of uniforms) group.push({ binding: u.binding, resource: { buffer: u.buffer } });
    return device.createBindGroup({ layout: bgl, entries: group });
  }
  // workgroups of a pass writing `o`; a frame pass (one with a stage) writes every layer per invocation
  function workgroups(ps, o) {
    const [lx, ly] = ps.local_size, [bx, by, bl] = ps.block || [1, 1, 1];
    return [Math.ceil(o.w / (lx * bx)), Math.ceil(o.h / (ly * by)), ps.stage ? 1 : o.layers / bl];
  }
  // a texture's read-back buffer (rows of a texture copy are padded to 256 bytes)
  function readbackOf(device, t) {
    const row = Math.ceil(t.w * TEXEL_BYTES[t.format] / 256) * 256;
    const buffer = device.createBuffer({ size: row * t.h * t.layers,
      usage: GPUBufferUsage.COPY_DST | GPUBufferUsage.MAP_READ });
    return { t, row, buffer };
  }
  // encode one compute pass of `steps` [{pipeline, group, groups}] and the copy into `rb`, submit, map:
  // resolves to the texels, Float32Array (layers, h, row / 4) in texture rows
  async function submit(device, steps, rb) {
    const encoder = device.createCommandEncoder();
    const pass = encoder.beginComputePass();
    for (const s of steps) {  // one pass encoder: WebGPU orders the dispatches
      pass.setPipeline(s.pipeline);
      pass.setBindGroup(0, s.group);
      pass.dispatchWorkgroups(...s.groups);
    }
    pass.end();
    const t = rb.t;
    encoder.copyTextureToBuffer({ texture: t.texture }, { buffer: rb.buffer, bytesPerRow: rb.row, rowsPerImage: t.h },
      [t.w, t.h, t.layers]);
    device.queue.submit([encoder.finish()]);
    await rb.buffer.mapAsync(GPUMapMode.READ);
    const raw = new Float32Array(rb.buffer.getMappedRange().slice(0));
    rb.buffer.unmap();
    return raw;
  }

  // ------------------------------------------------------------------ the network's passes
  // per (device, program): bind group layouts, pipelines, the weights buffer, uniform buffers
  function prepare(device, program) {
    const cached = program.__prepared;
    if (cached && cached.device === device) return cached;
    const m = program.manifest;
    if (m.format !== "neuralao-wgsl-compute") throw new Error("not a WGSL export");
    const weights = weightsBuffer(device, program.weights);
    const passes = m.passes.map((ps) => {
      const uniforms = Object.entries(ps.uniforms || {}).map(([name, u]) =>
        ({ name, binding: u.binding, onnx: u.onnx_input, isFlip: name === "u_flip_y", buffer: uniformBuffer(device, 16) }));
      const format = FORMATS[m.textures[ps.output.texture].format];
      const { bgl, pipeline } = pipelineOf(device, program, ps, format, uniforms.map((u) => u.binding));
      return { ps, bgl, pipeline, uniforms };
    });
    program.__prepared = { device, weights, passes, sized: null };
    return program.__prepared;
  }

  // per input size: textures, bind groups, the read-back buffer
  function sized(device, prep, m, width, height) {
    const key = width + "x" + height;
    if (prep.sized && prep.sized.key === key) return prep.sized;
    if (prep.sized) for (const t of Object.values(prep.sized.tex)) t.texture.destroy();
    const p = m.pad.multiple;
    const sizes = { W: width, H: height, Wp: Math.ceil(width / p) * p, Hp: Math.ceil(height / p) * p };
    const tex = {};
    for (const [id, t] of Object.entries(m.textures)) {
      tex[id] = texture(device, size(t.width, sizes), size(t.height, sizes), t.layers, FORMATS[t.format]);
    }
    const steps = prep.passes.map(({ ps, bgl, pipeline, uniforms }) =>
      ({ pipeline, group: bindGroupOf(device, ps, bgl, tex, prep.weights, uniforms),
        groups: workgroups(ps, tex[ps.output.texture]) }));
    prep.sized = { key, tex, steps, rb: readbackOf(device, tex[m.outputs[0].texture]) };
    return prep.sized;
  }

  async function run(device, program, x, width, height, scalars, flipY) {
    const m = program.manifest;
    const prep = prepare(device, program);
    const { tex, steps, rb } = sized(device, prep, m, width, height);
    // the input: channel c in layer c / 4, lane c % 4
    const input = tex[m.input.texture], c = m.input.channels;
    const texels = new Float32Array(input.layers * height * width * 4);
    for (let ch = 0; ch < c; ch++) {
      const layer = ch >> 2, lane = ch & 3;
      for (let i = 0; i < width * height; i++) texels[(layer * width * height + i) * 4 + lane] = x[ch * width * height + i];
    }
    device.queue.writeTexture({ texture: input.texture }, texels, { bytesPerRow: width * 16, rowsPerImage: height },
      [width, height, input.layers]);
    for (const { uniforms } of prep.passes) {
      for (const u of uniforms) {
        if (!u.isFlip && !(u.onnx in scalars)) throw new Error(`scalar input ${u.onnx} not given`);
        const value = u.isFlip ? (flipY ? 1 : 0) : scalars[u.onnx];
        const data = u.isFlip ? new Int32Array([value, 0, 0, 0]) : new Float32Array([value, 0, 0, 0]);
        device.queue.writeBuffer(u.buffer, 0, data);
      }
    }
    const raw = await submit(device, steps, rb);
    const res = rb.t, row = rb.row / 4;
    const channels = m.outputs[0].channels, out = new Float32Array(channels * res.w * res.h);
    for (let ch = 0; ch < channels; ch++) {
      const layer = ch >> 2, lane = ch & 3;
      for (let y = 0; y < res.h; y++)
        for (let xx = 0; xx < res.w; xx++)
          out[(ch * res.h + y) * res.w + xx] = raw[(layer * res.h + y) * row + xx * 4 + lane];
    }
    return out;
  }

  // ------------------------------------------------------------------ the whole frame
  // per (device, program): the weights, the frame's uniform buffers, pipelines made on first use
  function prepareFrame(device, program) {
    const cached = program.__frame;
    if (cached && cached.device === device) return cached;
    const m = program.manifest;
    if (m.format !== "neuralao-wgsl-compute") throw new Error("not a WGSL export");
    if (!m.frame) throw new Error("this export has no frame passes (manifest.frame)");
    program.__frame = { device, weights: weightsBuffer(device, program.weights),
      frameUniforms: uniformBuffer(device, FRAME_UNIFORM_BYTES), flip: uniformBuffer(device, 16),
      pipelines: {}, sized: null };
    return program.__frame;
  }

  // a step's pass entry, its uniform buffers and its pipeline (made once per pass)
  function stepPass(device, program, prep, step) {
    const m = program.manifest;
    const ps = "frame_pass" in step ? m.frame.passes.find((p) => p.name === step.frame_pass) : m.passes[step.index];
    if (!ps) throw new Error(`step ${JSON.stringify(step)} names no pass of the manifest`);
    const uniforms = [];
    if (ps.stage) uniforms.push({ binding: ps.uniform_block.binding, buffer: prep.frameUniforms });
    for (const [name, u] of Object.entries(ps.uniforms || {})) {
      if (name !== "u_flip_y") throw new Error(`pass ${ps.name}: the frame sets no uniform ${name}`);
      uniforms.push({ binding: u.binding, buffer: prep.flip });
    }
    if (!prep.pipelines[ps.name]) {
      const format = FORMATS[m.frame.textures[ps.output.texture].format];
      prep.pipelines[ps.name] = pipelineOf(device, program, ps, format, uniforms.map((u) => u.binding));
    }
    return { ps, uniforms, ...prep.pipelines[ps.name] };
  }

  // per frame size: every texture of the frame, the active steps' bind groups, the AO's read-back buffer
  function sizedFrame(device, program, prep, width, height) {
    const key = width + "x" + height;
    if (prep.sized && prep.sized.key === key) return prep.sized;
    if (prep.sized) for (const t of Object.values(prep.sized.tex)) t.texture.destroy();
    const m = program.manifest, sizes = frameSizes(m, width, height), tex = {};
    for (const [id, s] of Object.entries(sizes)) tex[id] = texture(device, s.w, s.h, s.layers, s.format);
    const steps = activeSteps(m, sizes, width, height).map((step) => {
      const { ps, uniforms, bgl, pipeline } = stepPass(device, program, prep, step);
      return { pipeline, group: bindGroupOf(device, ps, bgl, tex, prep.weights, uniforms),
        groups: workgroups(ps, tex[ps.output.texture]) };
    });
    const low = tex[m.input.texture];
    prep.sized = { key, tex, steps, internal: [low.w, low.h], rb: readbackOf(device, tex[m.frame.output]) };
    return prep.sized;
  }

  // FrameUniforms (std140, 32 bytes), as runtime/frame_runner.py uniform_bytes
  function frameUniformBytes(yfov, radius, width, height, flipY) {
    if (!(Number.isFinite(radius) && radius > 0)) throw new Error(`AO radius must be a positive finite distance, got ${radius}`);
    const f = 1 / Math.tan(yfov / 2), p00 = f / (width / height), p11 = f;
    const data = new ArrayBuffer(FRAME_UNIFORM_BYTES);
    new Float32Array(data, 0, 4).set([p00, p11, radius, 0.5 * height * p11]);
    new Int32Array(data, 16, 1)[0] = flipY ? 1 : 0;
    return data;
  }

  async function runFrame(device, program, depth, normal, width, height, camera, flipY) {
    // the inputs this runner feeds: a model that reads another (the back layer of input version 4) is
    // refused, never run with that texture left at zero
    const unfed = Object.keys(program.manifest.frame.inputs).filter((k) => k !== "depth" && k !== "normal");
    if (unfed.length) throw new Error(`the model reads the engine input ${unfed[0]}, which is not fed here`);
    const prep = prepareFrame(device, program);
    const { tex, steps, rb, internal } = sizedFrame(device, program, prep, width, height);
    if (depth.length !== width * height || normal.length !== 4 * width * height) {
      throw new Error(`depth and normal must hold ${width}x${height} texels`);
    }
    device.queue.writeTexture({ texture: tex.depth.texture }, depth, { bytesPerRow: width * 4, rowsPerImage: height },
      [width, height, 1]);
    device.queue.writeTexture({ texture: tex.normal.texture }, normal, { bytesPerRow: width * 16, rowsPerImage: height },
      [width, height, 1]);
    device.queue.writeBuffer(prep.frameUniforms, 0, frameUniformBytes(camera.yfov, camera.radius, width, height, flipY));
    device.queue.writeBuffer(prep.flip, 0, new Int32Array([flipY ? 1 : 0, 0, 0, 0]));
    const raw = await submit(device, steps, rb);
    const row = rb.row / 4, ao = new Float32Array(width * height);  // R32F: one float per texel
    for (let y = 0; y < height; y++) ao.set(raw.subarray(y * row, y * row + width), y * width);
    return { ao, internal };
  }

  // texture `id` of the latest runFrame of `program` (its frame size): Float32Array (layers, h, w, lanes),
  // texture rows, lanes 4 (RGBA) or 1 (R32F), as runtime/frame_runner.py FrameRunner.read
  async function readFrame(device, program, id) {
    const sizedNow = program.__frame && program.__frame.sized;
    if (!sizedNow || !sizedNow.tex[id]) throw new Error(`no texture ${id} of a frame run`);
    if (sizedNow.tex[id].format === "rgba16float") throw new Error(`texture ${id} is not 32-bit float`);
    const rb = readbackOf(device, sizedNow.tex[id]), t = rb.t, lanes = TEXEL_BYTES[t.format] / 4;
    const raw = await submit(device, [], rb), row = rb.row / 4;
    rb.buffer.destroy();
    const out = new Float32Array(t.layers * t.h * t.w * lanes);
    for (let y = 0; y < t.layers * t.h; y++) out.set(raw.subarray(y * row, y * row + t.w * lanes), y * t.w * lanes);
    return out;
  }

  window.neuralaoWgsl = { run, runFrame, readFrame };
})();
