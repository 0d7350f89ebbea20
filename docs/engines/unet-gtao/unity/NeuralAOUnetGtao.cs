// Generated from the manifests of unet-gtao by `python -m neuralao.export.glsl.engines`; tests/test_engine_wrappers.py checks it against the manifests and the exported shaders.
// Not run here (no Unity): the HLSL it binds, by these names and registers, runs the whole frame on
// Vulkan (lavapipe) in tests/test_frame_passes.py.
using System.Collections.Generic;
using UnityEngine;
using UnityEngine.Rendering;

/// <summary>The whole unet-gtao frame: 20 steps in the order of the manifest's frame.steps,
/// from the textures the engine writes to the AO texture "ao".
/// Each frame: Resize(W, H) when the size changes, write the inputs, Run(camera, radius), read AO.
/// The inputs (Texture(id), W x H):
///  depth: write each frame: linear depth -z_cam in scene units (lane 0), 0 on background; the passes reconstruct camera-space positions from it, the pixel and u_proj
///  normal: write each frame: camera-space unit normal (xyz), OpenGL axes, facing the viewer
/// </summary>
public sealed class NeuralAOUnetGtao : System.IDisposable
{
    public const int PadMultiple = 8;
    public const int InternalHeight = 256;  // network rows; 0: the network runs at W x H
    readonly ComputeShader shader;  // NeuralAOUnetGtao.compute
    readonly float[] weights;       // weights.bin as floats
    readonly Dictionary<int, GraphicsBuffer> passWeights = new Dictionary<int, GraphicsBuffer>();
    readonly Dictionary<string, RenderTexture> tex = new Dictionary<string, RenderTexture>();
    readonly GraphicsBuffer frameUniforms = new GraphicsBuffer(GraphicsBuffer.Target.Constant, 8, 4);
    bool sameSize;    // the network's input is W x H: the steps marked (w, h) == (W, H) run
    int frameHeight;  // H

    public NeuralAOUnetGtao(ComputeShader shader, byte[] weightsBin)
    {
        this.shader = shader;
        weights = new float[weightsBin.Length / 4];
        System.Buffer.BlockCopy(weightsBin, 0, weights, 0, weightsBin.Length);
        Weights(1, 0, 288);
        Weights(2, 512, 448);
        Weights(3, 1024, 1744);
        Weights(4, 2816, 1184);
        Weights(5, 4096, 4672);
        Weights(6, 8960, 18560);
        Weights(7, 27648, 18496);
        Weights(8, 46336, 18496);
        Weights(9, 65024, 4640);
        Weights(10, 69888, 4640);
        Weights(11, 74752, 1168);
        Weights(12, 76032, 1168);
        Weights(13, 77312, 288);
    }

    /// <summary>A buffer of the pass's own: its range of weights.bin (the HLSL reads from byte 0).</summary>
    void Weights(int pass, int offset, int bytes)
    {
        var b = new GraphicsBuffer(GraphicsBuffer.Target.Raw, bytes / 4, 4);
        b.SetData(weights, offset / 4, 0, bytes / 4);
        passWeights[pass] = b;
    }

    static RenderTexture Array2D(int w, int h, int layers, RenderTextureFormat format)
    {
        var t = new RenderTexture(w, h, 0, format)
        {
            dimension = TextureDimension.Tex2DArray, volumeDepth = layers, enableRandomWrite = true
        };
        t.Create();
        return t;
    }

    static int CeilDiv(int n, int d) => (n + d - 1) / d;

    public RenderTexture Texture(string id) => tex[id];
    public RenderTexture AO => tex["ao"];

    /// <summary>Allocate every texture of the frame (frame.textures) for a W x H frame: w x h the network's
    /// input (InternalHeight rows, the width rounded half to even), wp x hp those padded.</summary>
    public void Resize(int W, int H)
    {
        Release();
        frameHeight = H;
        int w = InternalHeight > 0 ? Mathf.Max(1, (int)System.Math.Round((double)W * InternalHeight / H)) : W;
        int h = InternalHeight > 0 ? InternalHeight : H;
        int wp = CeilDiv(w, PadMultiple) * PadMultiple, hp = CeilDiv(h, PadMultiple) * PadMultiple;
        tex["ao"] = Array2D(W, H, 1, RenderTextureFormat.RFloat);
        tex["depth"] = Array2D(W, H, 1, RenderTextureFormat.RFloat);
        tex["gtao"] = Array2D(W, H, 1, RenderTextureFormat.RFloat);
        tex["gtao_raw"] = Array2D(W, H, 1, RenderTextureFormat.RFloat);
        tex["low_gbuffer"] = Array2D(w, h, 3, RenderTextureFormat.ARGBFloat);
        tex["normal"] = Array2D(W, H, 1, RenderTextureFormat.ARGBFloat);
        tex["t0"] = Array2D(w, h, 2, RenderTextureFormat.ARGBFloat);
        tex["t12"] = Array2D(wp, hp, 2, RenderTextureFormat.ARGBFloat);
        tex["t14"] = Array2D(wp, hp, 1, RenderTextureFormat.ARGBFloat);
        tex["t16"] = Array2D(wp * 1 / 2, hp * 1 / 2, 2, RenderTextureFormat.ARGBFloat);
        tex["t18"] = Array2D(wp * 1 / 4, hp * 1 / 4, 4, RenderTextureFormat.ARGBFloat);
        tex["t2"] = Array2D(1, 1, 1, RenderTextureFormat.ARGBFloat);
        tex["t20"] = Array2D(wp * 1 / 8, hp * 1 / 8, 8, RenderTextureFormat.ARGBFloat);
        tex["t22"] = Array2D(wp * 1 / 4, hp * 1 / 4, 4, RenderTextureFormat.ARGBFloat);
        tex["t23"] = Array2D(wp * 1 / 4, hp * 1 / 4, 4, RenderTextureFormat.ARGBFloat);
        tex["t25"] = Array2D(wp * 1 / 2, hp * 1 / 2, 2, RenderTextureFormat.ARGBFloat);
        tex["t26"] = Array2D(wp * 1 / 2, hp * 1 / 2, 2, RenderTextureFormat.ARGBFloat);
        tex["t28"] = Array2D(wp, hp, 1, RenderTextureFormat.ARGBFloat);
        tex["t29"] = Array2D(wp, hp, 1, RenderTextureFormat.ARGBFloat);
        tex["t32"] = Array2D(w, h, 1, RenderTextureFormat.ARGBFloat);
        tex["t9"] = Array2D(wp, hp, 1, RenderTextureFormat.ARGBFloat);
        sameSize = tex["t0"].width == W && tex["t0"].height == H;
    }

    /// <summary>The frame for a camera: its projection, and the row order of the graphics API (row 0 is the
    /// top row on D3D, Vulkan and Metal; the bottom row on OpenGL).</summary>
    public void Run(Camera camera, float radius)
    {
        Matrix4x4 p = camera.projectionMatrix;
        Run(p.m00, p.m11, radius, !SystemInfo.graphicsUVStartsAtTop);
    }

    /// <summary>Every step in order. p00, p11: the projection's scales (f * H / W, f); radius in scene
    /// units; flipY: the textures are stored bottom-up (row 0 = the bottom row).</summary>
    public void Run(float p00, float p11, float radius, bool flipY)
    {
        int flip = flipY ? 1 : 0;
        float pixels_per_unit = 0.5f * frameHeight * p11;
        var u = new float[8];  // FrameUniforms (cbuffer, b0): 32 bytes
        u[0] = (float)(p00);  // frame_u_proj
        u[1] = (float)(p11);  // frame_u_proj
        u[2] = (float)(radius);  // frame_u_radius
        u[3] = (float)(pixels_per_unit);  // frame_u_pixels_per_unit
        u[4] = System.BitConverter.Int32BitsToSingle(flip);  // frame_u_flip_y
        frameUniforms.SetData(u);
        int k;
        // step 0: f_gtao: GTAO, 4 slices x 8 steps per side
        k = shader.FindKernel("f_gtao");
        shader.SetTexture(k, "src0", tex["depth"]);
        shader.SetTexture(k, "src1", tex["normal"]);
        shader.SetTexture(k, "dst", tex["gtao_raw"]);
        shader.SetConstantBuffer("FrameUniforms", frameUniforms, 0, 32);
        shader.Dispatch(k, CeilDiv(tex["gtao_raw"].width, 8), CeilDiv(tex["gtao_raw"].height, 8), 1);
        // step 1: f_gtao_blur: GTAO's 4x4 foreground-only blur
        k = shader.FindKernel("f_gtao_blur");
        shader.SetTexture(k, "src0", tex["depth"]);
        shader.SetTexture(k, "src1", tex["gtao_raw"]);
        shader.SetTexture(k, "dst", tex["gtao"]);
        shader.SetConstantBuffer("FrameUniforms", frameUniforms, 0, 32);
        shader.Dispatch(k, CeilDiv(tex["gtao"].width, 8), CeilDiv(tex["gtao"].height, 8), 1);
        // step 2: f_downsample: point sampling to the network's size, position from depth, GTAO
        k = shader.FindKernel("f_downsample");
        shader.SetTexture(k, "src0", tex["depth"]);
        shader.SetTexture(k, "src1", tex["normal"]);
        shader.SetTexture(k, "src2", tex["gtao"]);
        shader.SetTexture(k, "src3", tex["gtao_raw"]);
        shader.SetTexture(k, "dst", tex["low_gbuffer"]);
        shader.SetConstantBuffer("FrameUniforms", frameUniforms, 0, 32);
        shader.Dispatch(k, CeilDiv(tex["low_gbuffer"].width, 8), CeilDiv(tex["low_gbuffer"].height, 8), 1);
        // step 3: f_network_input: the network's input: log depth, normal, GTAO
        k = shader.FindKernel("f_network_input");
        shader.SetTexture(k, "src0", tex["low_gbuffer"]);
        shader.SetTexture(k, "dst", tex["t0"]);
        shader.SetConstantBuffer("FrameUniforms", frameUniforms, 0, 32);
        shader.Dispatch(k, CeilDiv(tex["t0"].width, 8), CeilDiv(tex["t0"].height, 8), 1);
        // step 4: f_network_radius: the network's radius input log(R P11)
        k = shader.FindKernel("f_network_radius");
        shader.SetTexture(k, "dst", tex["t2"]);
        shader.SetConstantBuffer("FrameUniforms", frameUniforms, 0, 32);
        shader.Dispatch(k, CeilDiv(tex["t2"].width, 1), CeilDiv(tex["t2"].height, 1), 1);
        // step 5: p00_uniform skipped: f_network_radius writes its texture
        // step 6: p01_pointwise: Pad + Mul + Conv + Mul + Clip + Conv + Sub + Mul + Neg + Exp + Clip + Mul
        k = shader.FindKernel("p01_pointwise");
        shader.SetTexture(k, "src0", tex["t0"]);
        shader.SetTexture(k, "src1", tex["t2"]);
        shader.SetTexture(k, "dst", tex["t9"]);
        shader.SetBuffer(k, "params", passWeights[1]);
        shader.SetInt("u_flip_y", flip);
        shader.Dispatch(k, CeilDiv(tex["t9"].width, 8), CeilDiv(tex["t9"].height, 8), 1);
        // step 7: p02_pointwise: Pad + Mul + Conv + Mul + Clip + Conv + Sub + Mul + Sub + Conv + Add
        k = shader.FindKernel("p02_pointwise");
        shader.SetTexture(k, "src0", tex["t0"]);
        shader.SetTexture(k, "src1", tex["t2"]);
        shader.SetTexture(k, "dst", tex["t12"]);
        shader.SetBuffer(k, "params", passWeights[2]);
        shader.SetInt("u_flip_y", flip);
        shader.Dispatch(k, CeilDiv(tex["t12"].width, 8), CeilDiv(tex["t12"].height, 8), 2);
        // step 8: p03_conv: Concat + Conv + LeakyRelu
        k = shader.FindKernel("p03_conv");
        shader.SetTexture(k, "src0", tex["t12"]);
        shader.SetTexture(k, "src1", tex["t9"]);
        shader.SetTexture(k, "dst", tex["t14"]);
        shader.SetBuffer(k, "params", passWeights[3]);
        shader.Dispatch(k, CeilDiv(tex["t14"].width, 8), CeilDiv(tex["t14"].height, 8), 1);
        // step 9: p04_conv: AveragePool + Conv + LeakyRelu
        k = shader.FindKernel("p04_conv");
        shader.SetTexture(k, "src0", tex["t14"]);
        shader.SetTexture(k, "dst", tex["t16"]);
        shader.SetBuffer(k, "params", passWeights[4]);
        shader.Dispatch(k, CeilDiv(tex["t16"].width, 8), CeilDiv(tex["t16"].height, 8), 2);
        // step 10: p05_conv: AveragePool + Conv + LeakyRelu
        k = shader.FindKernel("p05_conv");
        shader.SetTexture(k, "src0", tex["t16"]);
        shader.SetTexture(k, "dst", tex["t18"]);
        shader.SetBuffer(k, "params", passWeights[5]);
        shader.Dispatch(k, CeilDiv(tex["t18"].width, 8), CeilDiv(tex["t18"].height, 8), 4);
        // step 11: p06_conv: AveragePool + Conv + LeakyRelu
        k = shader.FindKernel("p06_conv");
        shader.SetTexture(k, "src0", tex["t18"]);
        shader.SetTexture(k, "dst", tex["t20"]);
        shader.SetBuffer(k, "params", passWeights[6]);
        shader.Dispatch(k, CeilDiv(tex["t20"].width, 8), CeilDiv(tex["t20"].height, 8), 8);
        // step 12: p07_conv: Resize + Conv + LeakyRelu
        k = shader.FindKernel("p07_conv");
        shader.SetTexture(k, "src0", tex["t20"]);
        shader.SetTexture(k, "dst", tex["t22"]);
        shader.SetBuffer(k, "params", passWeights[7]);
        shader.Dispatch(k, CeilDiv(tex["t22"].width, 8), CeilDiv(tex["t22"].height, 8), 4);
        // step 13: p08_conv: Concat + Conv + LeakyRelu
        k = shader.FindKernel("p08_conv");
        shader.SetTexture(k, "src0", tex["t22"]);
        shader.SetTexture(k, "src1", tex["t18"]);
        shader.SetTexture(k, "dst", tex["t23"]);
        shader.SetBuffer(k, "params", passWeights[8]);
        shader.Dispatch(k, CeilDiv(tex["t23"].width, 8), CeilDiv(tex["t23"].height, 8), 4);
        // step 14: p09_conv: Resize + Conv + LeakyRelu
        k = shader.FindKernel("p09_conv");
        shader.SetTexture(k, "src0", tex["t23"]);
        shader.SetTexture(k, "dst", tex["t25"]);
        shader.SetBuffer(k, "params", passWeights[9]);
        shader.Dispatch(k, CeilDiv(tex["t25"].width, 8), CeilDiv(tex["t25"].height, 8), 2);
        // step 15: p10_conv: Concat + Conv + LeakyRelu
        k = shader.FindKernel("p10_conv");
        shader.SetTexture(k, "src0", tex["t25"]);
        shader.SetTexture(k, "src1", tex["t16"]);
        shader.SetTexture(k, "dst", tex["t26"]);
        shader.SetBuffer(k, "params", passWeights[10]);
        shader.Dispatch(k, CeilDiv(tex["t26"].width, 8), CeilDiv(tex["t26"].height, 8), 2);
        // step 16: p11_conv: Resize + Conv + LeakyRelu
        k = shader.FindKernel("p11_conv");
        shader.SetTexture(k, "src0", tex["t26"]);
        shader.SetTexture(k, "dst", tex["t28"]);
        shader.SetBuffer(k, "params", passWeights[11]);
        shader.Dispatch(k, CeilDiv(tex["t28"].width, 8), CeilDiv(tex["t28"].height, 8), 1);
        // step 17: p12_conv: Concat + Conv + LeakyRelu
        k = shader.FindKernel("p12_conv");
        shader.SetTexture(k, "src0", tex["t28"]);
        shader.SetTexture(k, "src1", tex["t14"]);
        shader.SetTexture(k, "dst", tex["t29"]);
        shader.SetBuffer(k, "params", passWeights[12]);
        shader.Dispatch(k, CeilDiv(tex["t29"].width, 8), CeilDiv(tex["t29"].height, 8), 1);
        // step 18: p13_pointwise: Concat + Conv + Conv + Add + Clip + Crop
        k = shader.FindKernel("p13_pointwise");
        shader.SetTexture(k, "src0", tex["t12"]);
        shader.SetTexture(k, "src1", tex["t9"]);
        shader.SetTexture(k, "src2", tex["t29"]);
        shader.SetTexture(k, "dst", tex["t32"]);
        shader.SetBuffer(k, "params", passWeights[13]);
        shader.SetInt("u_flip_y", flip);
        shader.Dispatch(k, CeilDiv(tex["t32"].width, 8), CeilDiv(tex["t32"].height, 8), 1);
        if (!sameSize)  // (w, h) != (W, H)
        {
            // step 19: f_upsample: joint bilateral upsampling of the correction to GTAO, added to GTAO and clamped
            k = shader.FindKernel("f_upsample");
            shader.SetTexture(k, "src0", tex["depth"]);
            shader.SetTexture(k, "src1", tex["normal"]);
            shader.SetTexture(k, "src2", tex["t32"]);
            shader.SetTexture(k, "src3", tex["low_gbuffer"]);
            shader.SetTexture(k, "src4", tex["gtao"]);
            shader.SetTexture(k, "dst", tex["ao"]);
            shader.SetConstantBuffer("FrameUniforms", frameUniforms, 0, 32);
            shader.Dispatch(k, CeilDiv(tex["ao"].width, 8), CeilDiv(tex["ao"].height, 8), 1);
        }
        if (sameSize)  // (w, h) == (W, H)
        {
            // step 20: f_composite: the network's AO, 1 on background
            k = shader.FindKernel("f_composite");
            shader.SetTexture(k, "src0", tex["depth"]);
            shader.SetTexture(k, "src1", tex["t32"]);
            shader.SetTexture(k, "dst", tex["ao"]);
            shader.SetConstantBuffer("FrameUniforms", frameUniforms, 0, 32);
            shader.Dispatch(k, CeilDiv(tex["ao"].width, 8), CeilDiv(tex["ao"].height, 8), 1);
        }
    }

    void Release()
    {
        foreach (var t in tex.Values) t.Release();
        tex.Clear();
    }

    public void Dispose()
    {
        Release();
        foreach (var b in passWeights.Values) b.Release();
        frameUniforms.Release();
    }
}
