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
"use strict";

(function () {
  const FORMATS = { RGBA32F: "rgba32float", RGBA16F: "rgba16float" };

  function size(dim, sizes) {
    const v = sizes[dim.of] * dim.num;
    if (v % dim.den) throw new Error(`texture size ${dim.formula} is fractional for ${dim.of} = ${sizes[dim.of]}`);
    return v / dim.den + dim.offset;
  }

  function uniformBuffer(device, value, isInt) {
    const data = isInt ? new Int32Array([value, 0, 0, 0]) : new Float32Array([value, 0, 0, 0]);
    const buf = device.createBuffer({ size: 16, usage: GPUBufferUsage.UNIFORM | GPUBufferUsage.COPY_DST });
    device.queue.writeBuffer(buf, 0, data);
    return buf;
  }

  async function run(device, program, x, width, height, scalars, flipY) {
    const m = program.manifest;
    if (m.format !== "neuralao-wgsl-compute") throw new Error("not a WGSL export");
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
    // the input: channel c in layer c / 4, lane c % 4
    const input = tex[m.input.texture], c = m.input.channels;
    const texels = new Float32Array(input.layers * height * width * 4);
    for (let ch = 0; ch < c; ch++) {
      const layer = ch >> 2, lane = ch & 3;
      for (let i = 0; i < width * height; i++) texels[(layer * width * height + i) * 4 + lane] = x[ch * width * height + i];
    }
    device.queue.writeTexture({ texture: input.texture }, texels, { bytesPerRow: width * 16, rowsPerImage: height },
      [width, height, input.layers]);
    const weights = device.createBuffer({ size: Math.max(16, program.weights.byteLength), usage: GPUBufferUsage.STORAGE,
      mappedAtCreation: true });
    new Uint8Array(weights.getMappedRange()).set(new Uint8Array(program.weights));
    weights.unmap();

    const encoder = device.createCommandEncoder();
    const pass = encoder.beginComputePass();
    const C = GPUShaderStage.COMPUTE;
    for (const ps of m.passes) {
      const layout = [], group = [];
      for (const inp of ps.inputs) {
        layout.push({ binding: inp.binding, visibility: C, texture: { sampleType: "unfilterable-float", viewDimension: "2d-array" } });
        group.push({ binding: inp.binding, resource: tex[inp.texture].view });
      }
      const out = ps.output;
      layout.push({ binding: out.binding, visibility: C,
        storageTexture: { access: "write-only", format: out.format, viewDimension: "2d-array" } });
      group.push({ binding: out.binding, resource: tex[out.texture].view });
      if (ps.params) {
        layout.push({ binding: ps.params.binding, visibility: C, buffer: { type: "read-only-storage" } });
        group.push({ binding: ps.params.binding, resource: { buffer: weights, offset: ps.params.offset, size: ps.params.bytes } });
      }
      for (const [name, u] of Object.entries(ps.uniforms || {})) {
        const isFlip = name === "u_flip_y";
        if (!isFlip && !(u.onnx_input in scalars)) throw new Error(`scalar input ${u.onnx_input} not given`);
        layout.push({ binding: u.binding, visibility: C, buffer: { type: "uniform" } });
        group.push({ binding: u.binding, resource: { buffer: uniformBuffer(device, isFlip ? (flipY ? 1 : 0) : scalars[u.onnx_input], isFlip) } });
      }
      const bgl = device.createBindGroupLayout({ entries: layout });
      const module = device.createShaderModule({ code: program.sources[ps.shader] });
      const pipeline = device.createComputePipeline({
        layout: device.createPipelineLayout({ bindGroupLayouts: [bgl] }), compute: { module, entryPoint: "main" },
      });
      const o = tex[out.texture], [lx, ly] = ps.local_size, [bx, by, bl] = ps.block || [1, 1, 1];
      pass.setPipeline(pipeline);
      pass.setBindGroup(0, device.createBindGroup({ layout: bgl, entries: group }));
      pass.dispatchWorkgroups(Math.ceil(o.w / (lx * bx)), Math.ceil(o.h / (ly * by)), o.layers / bl);
    }
    pass.end();
    // read back the first output: rows padded to 256 bytes
    const res = tex[m.outputs[0].texture];
    const row = Math.ceil(res.w * 16 / 256) * 256;
    const readback = device.createBuffer({ size: row * res.h * res.layers, usage: GPUBufferUsage.COPY_DST | GPUBufferUsage.MAP_READ });
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
    for (const t of Object.values(tex)) t.texture.destroy();
    return outArr;
  }

  window.neuralaoWgsl = { run };
})();
