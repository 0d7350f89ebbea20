// neuralao WGSL runner for the browser (WebGPU): the JavaScript twin of runtime/wgsl_runner.py.
// Runs a `neuralao-wgsl-compute` export (manifest, .wgsl sources, weights.bin) exactly as its manifest
// says: textures at their size formulas, one bind group per pass, the passes in one compute pass
// encoder, the first output read back. No dependencies.
//
//   const out = await neuralaoWgsl.run(device, program, x, width, height, scalars, flipY);
//     program : {manifest, sources: {file name: WGSL text}, weights: ArrayBuffer}
//     x       : Float32Array (C, H, W) of the input, C = manifest.input.channels, row 0 = the top row
//     scalars : {onnx input name: number} for the manifest's uniforms (e.g. {radius: rho})
//     returns Float32Array (C_out, H, W) of the first output
//
// The pipelines and the weights buffer are made once per (device, program) and the textures, bind
// groups and read-back buffer once per input size, so a viewer that runs the network every frame
// compiles nothing after its first frame. Calls on one program must not overlap (await each).
"use strict";

(function () {
  const FORMATS = { RGBA32F: "rgba32float", RGBA16F: "rgba16float" };

  function size(dim, sizes) {
    const v = sizes[dim.of] * dim.num;
    if (v % dim.den) throw new Error(`texture size ${dim.formula} is fractional for ${dim.of} = ${sizes[dim.of]}`);
    return v / dim.den + dim.offset;
  }

  // per (device, program): bind group layouts, pipelines, the weights buffer
  function prepare(device, program) {
    const cached = program.__prepared;
    if (cached && cached.device === device) return cached;
    const m = program.manifest;
    if (m.format !== "neuralao-wgsl-compute") throw new Error("not a WGSL export");
    const weights = device.createBuffer({ size: Math.max(16, program.weights.byteLength),
      usage: GPUBufferUsage.STORAGE, mappedAtCreation: true });
    new Uint8Array(weights.getMappedRange()).set(new Uint8Array(program.weights));
    weights.unmap();
    const C = GPUShaderStage.COMPUTE;
    const passes = m.passes.map((ps) => {
      const layout = [];
      for (const inp of ps.inputs) {
        layout.push({ binding: inp.binding, visibility: C,
          texture: { sampleType: "unfilterable-float", viewDimension: "2d-array" } });
      }
      layout.push({ binding: ps.output.binding, visibility: C,
        storageTexture: { access: "write-only", format: ps.output.format, viewDimension: "2d-array" } });
      if (ps.params) {
        layout.push({ binding: ps.params.binding, visibility: C, buffer: { type: "read-only-storage" } });
      }
      const uniforms = Object.entries(ps.uniforms || {}).map(([name, u]) => {
        layout.push({ binding: u.binding, visibility: C, buffer: { type: "uniform" } });
        const buffer = device.createBuffer({ size: 16,
          usage: GPUBufferUsage.UNIFORM | GPUBufferUsage.COPY_DST });
        return { name, binding: u.binding, onnx: u.onnx_input, isFlip: name === "u_flip_y", buffer };
      });
      const bgl = device.createBindGroupLayout({ entries: layout });
      const module = device.createShaderModule({ code: program.sources[ps.shader] });
      const pipeline = device.createComputePipeline({
        layout: device.createPipelineLayout({ bindGroupLayouts: [bgl] }),
        compute: { module, entryPoint: "main" },
      });
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
    const U = GPUTextureUsage;
    const tex = {};
    for (const [id, t] of Object.entries(m.textures)) {
      const w = size(t.width, sizes), h = size(t.height, sizes);
      const texture = device.createTexture({
        size: [w, h, t.layers], format: FORMATS[t.format], dimension: "2d",
        usage: U.TEXTURE_BINDING | U.STORAGE_BINDING | U.COPY_DST | U.COPY_SRC,
      });
      tex[id] = { texture, view: texture.createView({ dimension: "2d-array" }), w, h, layers: t.layers };
    }
    const groups = prep.passes.map(({ ps, bgl, uniforms }) => {
      const group = ps.inputs.map((inp) => ({ binding: inp.binding, resource: tex[inp.texture].view }));
      group.push({ binding: ps.output.binding, resource: tex[ps.output.texture].view });
      if (ps.params) {
        group.push({ binding: ps.params.binding,
          resource: { buffer: prep.weights, offset: ps.params.offset, size: ps.params.bytes } });
      }
      for (const u of uniforms) group.push({ binding: u.binding, resource: { buffer: u.buffer } });
      return device.createBindGroup({ layout: bgl, entries: group });
    });
    const res = tex[m.outputs[0].texture];
    const row = Math.ceil(res.w * 16 / 256) * 256;  // rows of a texture copy are padded to 256 bytes
    const readback = device.createBuffer({ size: row * res.h * res.layers,
      usage: GPUBufferUsage.COPY_DST | GPUBufferUsage.MAP_READ });
    prep.sized = { key, tex, groups, res, row, readback };
    return prep.sized;
  }

  async function run(device, program, x, width, height, scalars, flipY) {
    const m = program.manifest;
    const prep = prepare(device, program);
    const { tex, groups, res, row, readback } = sized(device, prep, m, width, height);
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
    const encoder = device.createCommandEncoder();
    const pass = encoder.beginComputePass();
    prep.passes.forEach(({ ps, pipeline }, k) => {
      const o = tex[ps.output.texture], [lx, ly] = ps.local_size, [bx, by, bl] = ps.block || [1, 1, 1];
      pass.setPipeline(pipeline);
      pass.setBindGroup(0, groups[k]);
      pass.dispatchWorkgroups(Math.ceil(o.w / (lx * bx)), Math.ceil(o.h / (ly * by)), o.layers / bl);
    });
    pass.end();
    encoder.copyTextureToBuffer({ texture: res.texture }, { buffer: readback, bytesPerRow: row, rowsPerImage: res.h },
      [res.w, res.h, res.layers]);
    device.queue.submit([encoder.finish()]);
    await readback.mapAsync(GPUMapMode.READ);
    const raw = new Float32Array(readback.getMappedRange().slice(0));
    readback.unmap();
    const channels = m.outputs[0].channels, outArr = new Float32Array(channels * res.w * res.h);
    for (let ch = 0; ch < channels; ch++) {
      const layer = ch >> 2, lane = ch & 3;
      for (let y = 0; y < res.h; y++)
        for (let xx = 0; xx < res.w; xx++)
          outArr[(ch * res.h + y) * res.w + xx] = raw[(layer * res.h * row / 4) + y * row / 4 + xx * 4 + lane];
    }
    return outArr;
  }

  window.neuralaoWgsl = { run };
})();
