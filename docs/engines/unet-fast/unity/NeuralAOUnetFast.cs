// Generated from the manifest of unet-fast by `python -m neuralao.export.glsl.engines`; tests/test_engine_wrappers.py checks it against the manifest and the generated shaders.
// Not run here (no Unity): the HLSL it binds, by these names, runs on Vulkan in tests/test_hlsl_target.py.
using System.Collections.Generic;
using UnityEngine;
using UnityEngine.Rendering;

/// <summary>The unet-fast network: 20 compute passes from the input texture t0 (fill it
/// first: 4 channels, 4 a layer) to the output t22.</summary>
public sealed class NeuralAOUnetFast : System.IDisposable
{
    public const int PadMultiple = 8;
    readonly ComputeShader shader;  // NeuralAOUnetFast.compute
    readonly float[] weights;       // weights.bin as floats
    readonly Dictionary<int, GraphicsBuffer> passWeights = new Dictionary<int, GraphicsBuffer>();
    readonly Dictionary<string, RenderTexture> tex = new Dictionary<string, RenderTexture>();

    public NeuralAOUnetFast(ComputeShader shader, byte[] weightsBin)
    {
        this.shader = shader;
        weights = new float[weightsBin.Length / 4];
        System.Buffer.BlockCopy(weightsBin, 0, weights, 0, weightsBin.Length);
        Weights(2, 0, 80);
        Weights(3, 256, 2336);
        Weights(5, 2816, 4672);
        Weights(7, 7680, 18560);
        Weights(9, 26368, 73984);
        Weights(11, 100352, 73856);
        Weights(12, 174336, 73856);
        Weights(14, 248320, 18496);
        Weights(15, 267008, 18496);
        Weights(17, 285696, 4640);
        Weights(18, 290560, 4640);
        Weights(19, 295424, 144);
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

    public RenderTexture Input => tex["t0"];
    public RenderTexture Output => tex["t22"];

    /// <summary>Allocate every texture for a width x height frame (both at least PadMultiple).</summary>
    public void Resize(int W, int H)
    {
        Release();
        int Wp = CeilDiv(W, PadMultiple) * PadMultiple, Hp = CeilDiv(H, PadMultiple) * PadMultiple;
        tex["t0"] = Array2D(W, H, 1, RenderTextureFormat.ARGBFloat);
        tex["t1"] = Array2D(Wp, Hp, 1, RenderTextureFormat.ARGBFloat);
        tex["t2"] = Array2D(1, 1, 1, RenderTextureFormat.ARGBFloat);
        tex["t4"] = Array2D(Wp, Hp, 1, RenderTextureFormat.ARGBFloat);
        tex["t5"] = Array2D(Wp, Hp, 2, RenderTextureFormat.ARGBFloat);
        tex["t6"] = Array2D(Wp * 1 / 2, Hp * 1 / 2, 2, RenderTextureFormat.ARGBFloat);
        tex["t7"] = Array2D(Wp * 1 / 2, Hp * 1 / 2, 4, RenderTextureFormat.ARGBFloat);
        tex["t8"] = Array2D(Wp * 1 / 4, Hp * 1 / 4, 4, RenderTextureFormat.ARGBFloat);
        tex["t9"] = Array2D(Wp * 1 / 4, Hp * 1 / 4, 8, RenderTextureFormat.ARGBFloat);
        tex["t10"] = Array2D(Wp * 1 / 8, Hp * 1 / 8, 8, RenderTextureFormat.ARGBFloat);
        tex["t11"] = Array2D(Wp * 1 / 8, Hp * 1 / 8, 16, RenderTextureFormat.ARGBFloat);
        tex["t12"] = Array2D(Wp * 1 / 4, Hp * 1 / 4, 16, RenderTextureFormat.ARGBFloat);
        tex["t13"] = Array2D(Wp * 1 / 4, Hp * 1 / 4, 8, RenderTextureFormat.ARGBFloat);
        tex["t14"] = Array2D(Wp * 1 / 4, Hp * 1 / 4, 8, RenderTextureFormat.ARGBFloat);
        tex["t15"] = Array2D(Wp * 1 / 2, Hp * 1 / 2, 8, RenderTextureFormat.ARGBFloat);
        tex["t16"] = Array2D(Wp * 1 / 2, Hp * 1 / 2, 4, RenderTextureFormat.ARGBFloat);
        tex["t17"] = Array2D(Wp * 1 / 2, Hp * 1 / 2, 4, RenderTextureFormat.ARGBFloat);
        tex["t18"] = Array2D(Wp, Hp, 4, RenderTextureFormat.ARGBFloat);
        tex["t19"] = Array2D(Wp, Hp, 2, RenderTextureFormat.ARGBFloat);
        tex["t20"] = Array2D(Wp, Hp, 2, RenderTextureFormat.ARGBFloat);
        tex["t22"] = Array2D(W, H, 1, RenderTextureFormat.ARGBFloat);
    }

    /// <summary>Every pass in order. flipY: the input and output are bottom-up (row 0 at the bottom).</summary>
    public void Run(float u_radius, bool flipY)
    {
        int k;
        // p00_pad: Pad
        k = shader.FindKernel("p00_pad");
        shader.SetTexture(k, "src0", tex["t0"]);
        shader.SetTexture(k, "dst", tex["t1"]);
        shader.SetInt("u_flip_y", flipY ? 1 : 0);
        shader.Dispatch(k, CeilDiv(tex["t1"].width, 8), CeilDiv(tex["t1"].height, 8), 1);
        // p01_uniform: Uniform
        k = shader.FindKernel("p01_uniform");
        shader.SetTexture(k, "dst", tex["t2"]);
        shader.SetFloat("u_radius", u_radius);
        shader.Dispatch(k, CeilDiv(tex["t2"].width, 8), CeilDiv(tex["t2"].height, 8), 1);
        // p02_conv: Conv + Clip + Div + Clip
        k = shader.FindKernel("p02_conv");
        shader.SetTexture(k, "src0", tex["t1"]);
        shader.SetTexture(k, "src1", tex["t2"]);
        shader.SetTexture(k, "dst", tex["t4"]);
        shader.SetBuffer(k, "params", passWeights[2]);
        shader.Dispatch(k, CeilDiv(tex["t4"].width, 8), CeilDiv(tex["t4"].height, 8), 1);
        // p03_conv: Concat + Conv + LeakyRelu
        k = shader.FindKernel("p03_conv");
        shader.SetTexture(k, "src0", tex["t1"]);
        shader.SetTexture(k, "src1", tex["t4"]);
        shader.SetTexture(k, "dst", tex["t5"]);
        shader.SetBuffer(k, "params", passWeights[3]);
        shader.Dispatch(k, CeilDiv(tex["t5"].width, 8), CeilDiv(tex["t5"].height, 8), 2);
        // p04_pool_avg: AveragePool
        k = shader.FindKernel("p04_pool_avg");
        shader.SetTexture(k, "src0", tex["t5"]);
        shader.SetTexture(k, "dst", tex["t6"]);
        shader.Dispatch(k, CeilDiv(tex["t6"].width, 8), CeilDiv(tex["t6"].height, 8), 2);
        // p05_conv: Conv + LeakyRelu
        k = shader.FindKernel("p05_conv");
        shader.SetTexture(k, "src0", tex["t6"]);
        shader.SetTexture(k, "dst", tex["t7"]);
        shader.SetBuffer(k, "params", passWeights[5]);
        shader.Dispatch(k, CeilDiv(tex["t7"].width, 8), CeilDiv(tex["t7"].height, 8), 4);
        // p06_pool_avg: AveragePool
        k = shader.FindKernel("p06_pool_avg");
        shader.SetTexture(k, "src0", tex["t7"]);
        shader.SetTexture(k, "dst", tex["t8"]);
        shader.Dispatch(k, CeilDiv(tex["t8"].width, 8), CeilDiv(tex["t8"].height, 8), 4);
        // p07_conv: Conv + LeakyRelu
        k = shader.FindKernel("p07_conv");
        shader.SetTexture(k, "src0", tex["t8"]);
        shader.SetTexture(k, "dst", tex["t9"]);
        shader.SetBuffer(k, "params", passWeights[7]);
        shader.Dispatch(k, CeilDiv(tex["t9"].width, 8), CeilDiv(tex["t9"].height, 8), 8);
        // p08_pool_avg: AveragePool
        k = shader.FindKernel("p08_pool_avg");
        shader.SetTexture(k, "src0", tex["t9"]);
        shader.SetTexture(k, "dst", tex["t10"]);
        shader.Dispatch(k, CeilDiv(tex["t10"].width, 8), CeilDiv(tex["t10"].height, 8), 8);
        // p09_conv: Conv + LeakyRelu
        k = shader.FindKernel("p09_conv");
        shader.SetTexture(k, "src0", tex["t10"]);
        shader.SetTexture(k, "dst", tex["t11"]);
        shader.SetBuffer(k, "params", passWeights[9]);
        shader.Dispatch(k, CeilDiv(tex["t11"].width, 8), CeilDiv(tex["t11"].height, 8), 16);
        // p10_resize_linear: Resize
        k = shader.FindKernel("p10_resize_linear");
        shader.SetTexture(k, "src0", tex["t11"]);
        shader.SetTexture(k, "dst", tex["t12"]);
        shader.Dispatch(k, CeilDiv(tex["t12"].width, 8), CeilDiv(tex["t12"].height, 8), 16);
        // p11_conv: Conv + LeakyRelu
        k = shader.FindKernel("p11_conv");
        shader.SetTexture(k, "src0", tex["t12"]);
        shader.SetTexture(k, "dst", tex["t13"]);
        shader.SetBuffer(k, "params", passWeights[11]);
        shader.Dispatch(k, CeilDiv(tex["t13"].width, 8), CeilDiv(tex["t13"].height, 8), 8);
        // p12_conv: Concat + Conv + LeakyRelu
        k = shader.FindKernel("p12_conv");
        shader.SetTexture(k, "src0", tex["t13"]);
        shader.SetTexture(k, "src1", tex["t9"]);
        shader.SetTexture(k, "dst", tex["t14"]);
        shader.SetBuffer(k, "params", passWeights[12]);
        shader.Dispatch(k, CeilDiv(tex["t14"].width, 8), CeilDiv(tex["t14"].height, 8), 8);
        // p13_resize_linear: Resize
        k = shader.FindKernel("p13_resize_linear");
        shader.SetTexture(k, "src0", tex["t14"]);
        shader.SetTexture(k, "dst", tex["t15"]);
        shader.Dispatch(k, CeilDiv(tex["t15"].width, 8), CeilDiv(tex["t15"].height, 8), 8);
        // p14_conv: Conv + LeakyRelu
        k = shader.FindKernel("p14_conv");
        shader.SetTexture(k, "src0", tex["t15"]);
        shader.SetTexture(k, "dst", tex["t16"]);
        shader.SetBuffer(k, "params", passWeights[14]);
        shader.Dispatch(k, CeilDiv(tex["t16"].width, 8), CeilDiv(tex["t16"].height, 8), 4);
        // p15_conv: Concat + Conv + LeakyRelu
        k = shader.FindKernel("p15_conv");
        shader.SetTexture(k, "src0", tex["t16"]);
        shader.SetTexture(k, "src1", tex["t7"]);
        shader.SetTexture(k, "dst", tex["t17"]);
        shader.SetBuffer(k, "params", passWeights[15]);
        shader.Dispatch(k, CeilDiv(tex["t17"].width, 8), CeilDiv(tex["t17"].height, 8), 4);
        // p16_resize_linear: Resize
        k = shader.FindKernel("p16_resize_linear");
        shader.SetTexture(k, "src0", tex["t17"]);
        shader.SetTexture(k, "dst", tex["t18"]);
        shader.Dispatch(k, CeilDiv(tex["t18"].width, 8), CeilDiv(tex["t18"].height, 8), 4);
        // p17_conv: Conv + LeakyRelu
        k = shader.FindKernel("p17_conv");
        shader.SetTexture(k, "src0", tex["t18"]);
        shader.SetTexture(k, "dst", tex["t19"]);
        shader.SetBuffer(k, "params", passWeights[17]);
        shader.Dispatch(k, CeilDiv(tex["t19"].width, 8), CeilDiv(tex["t19"].height, 8), 2);
        // p18_conv: Concat + Conv + LeakyRelu
        k = shader.FindKernel("p18_conv");
        shader.SetTexture(k, "src0", tex["t19"]);
        shader.SetTexture(k, "src1", tex["t5"]);
        shader.SetTexture(k, "dst", tex["t20"]);
        shader.SetBuffer(k, "params", passWeights[18]);
        shader.Dispatch(k, CeilDiv(tex["t20"].width, 8), CeilDiv(tex["t20"].height, 8), 2);
        // p19_conv: Conv + Sigmoid + Crop
        k = shader.FindKernel("p19_conv");
        shader.SetTexture(k, "src0", tex["t20"]);
        shader.SetTexture(k, "dst", tex["t22"]);
        shader.SetBuffer(k, "params", passWeights[19]);
        shader.SetInt("u_flip_y", flipY ? 1 : 0);
        shader.Dispatch(k, CeilDiv(tex["t22"].width, 8), CeilDiv(tex["t22"].height, 8), 1);
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
    }
}
