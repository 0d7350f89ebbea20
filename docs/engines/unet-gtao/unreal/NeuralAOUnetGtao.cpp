// Generated from the manifest of unet-gtao by `python -m neuralao.export.glsl.engines`; tests/test_engine_wrappers.py checks it against the manifest and the generated shaders.
#include "NeuralAOUnetGtao.h"

#include "RenderGraphUtils.h"

namespace NeuralAOUnetGtao
{
IMPLEMENT_GLOBAL_SHADER(Fp00_pad, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p00_pad", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp01_uniform, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p01_uniform", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp02_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p02_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp03_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p03_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp04_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p04_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp05_pool_avg, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p05_pool_avg", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp06_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p06_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp07_pool_avg, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p07_pool_avg", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp08_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p08_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp09_pool_avg, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p09_pool_avg", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp10_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p10_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp11_resize_linear, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p11_resize_linear", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp12_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p12_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp13_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p13_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp14_resize_linear, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p14_resize_linear", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp15_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p15_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp16_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p16_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp17_resize_linear, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p17_resize_linear", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp18_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p18_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp19_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p19_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp20_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p20_conv", SF_Compute);

void AddPasses(FRDGBuilder& GraphBuilder, const FResources& R, float u_radius, bool bFlipY)
{
    FGlobalShaderMap* ShaderMap = GetGlobalShaderMap(GMaxRHIFeatureLevel);
    auto Srv = [&](const TCHAR* T) { return GraphBuilder.CreateSRV(FRDGTextureSRVDesc::Create(R.Textures[T])); };
    auto Uav = [&](const TCHAR* T) { return GraphBuilder.CreateUAV(FRDGTextureUAVDesc(R.Textures[T])); };
    // each weights buffer made with FRDGBufferDesc::CreateByteAddressDesc(bytes): a raw view
    auto Raw = [&](int32 Pass) { return GraphBuilder.CreateSRV(R.Weights[Pass]); };
    auto Size = [&](const TCHAR* T) { return R.Textures[T]->Desc.Extent; };
    {  // p00_pad: Pad
        auto* P = GraphBuilder.AllocParameters<Fp00_pad::FParameters>();
        P->src0 = Srv(TEXT("t0"));
        P->dst = Uav(TEXT("t1"));
        P->u_flip_y = bFlipY ? 1 : 0;
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p00_pad"), TShaderMapRef<Fp00_pad>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t1")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t1")).Y, 8), 2));
    }
    {  // p01_uniform: Uniform
        auto* P = GraphBuilder.AllocParameters<Fp01_uniform::FParameters>();
        P->dst = Uav(TEXT("t2"));
        P->u_radius = u_radius;
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p01_uniform"), TShaderMapRef<Fp01_uniform>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t2")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t2")).Y, 8), 1));
    }
    {  // p02_conv: Conv + Clip + Div + Clip
        auto* P = GraphBuilder.AllocParameters<Fp02_conv::FParameters>();
        P->src0 = Srv(TEXT("t1"));
        P->src1 = Srv(TEXT("t2"));
        P->dst = Uav(TEXT("t4"));
        P->params = Raw(2);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p02_conv"), TShaderMapRef<Fp02_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t4")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t4")).Y, 8), 1));
    }
    {  // p03_conv: Concat + Conv
        auto* P = GraphBuilder.AllocParameters<Fp03_conv::FParameters>();
        P->src0 = Srv(TEXT("t1"));
        P->src1 = Srv(TEXT("t4"));
        P->dst = Uav(TEXT("t5"));
        P->params = Raw(3);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p03_conv"), TShaderMapRef<Fp03_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t5")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t5")).Y, 8), 1));
    }
    {  // p04_conv: Concat + Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp04_conv::FParameters>();
        P->src0 = Srv(TEXT("t1"));
        P->src1 = Srv(TEXT("t4"));
        P->dst = Uav(TEXT("t6"));
        P->params = Raw(4);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p04_conv"), TShaderMapRef<Fp04_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t6")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t6")).Y, 8), 1));
    }
    {  // p05_pool_avg: AveragePool
        auto* P = GraphBuilder.AllocParameters<Fp05_pool_avg::FParameters>();
        P->src0 = Srv(TEXT("t6"));
        P->dst = Uav(TEXT("t7"));
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p05_pool_avg"), TShaderMapRef<Fp05_pool_avg>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t7")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t7")).Y, 8), 1));
    }
    {  // p06_conv: Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp06_conv::FParameters>();
        P->src0 = Srv(TEXT("t7"));
        P->dst = Uav(TEXT("t8"));
        P->params = Raw(6);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p06_conv"), TShaderMapRef<Fp06_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t8")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t8")).Y, 8), 2));
    }
    {  // p07_pool_avg: AveragePool
        auto* P = GraphBuilder.AllocParameters<Fp07_pool_avg::FParameters>();
        P->src0 = Srv(TEXT("t8"));
        P->dst = Uav(TEXT("t9"));
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p07_pool_avg"), TShaderMapRef<Fp07_pool_avg>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t9")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t9")).Y, 8), 2));
    }
    {  // p08_conv: Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp08_conv::FParameters>();
        P->src0 = Srv(TEXT("t9"));
        P->dst = Uav(TEXT("t10"));
        P->params = Raw(8);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p08_conv"), TShaderMapRef<Fp08_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t10")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t10")).Y, 8), 4));
    }
    {  // p09_pool_avg: AveragePool
        auto* P = GraphBuilder.AllocParameters<Fp09_pool_avg::FParameters>();
        P->src0 = Srv(TEXT("t10"));
        P->dst = Uav(TEXT("t11"));
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p09_pool_avg"), TShaderMapRef<Fp09_pool_avg>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t11")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t11")).Y, 8), 4));
    }
    {  // p10_conv: Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp10_conv::FParameters>();
        P->src0 = Srv(TEXT("t11"));
        P->dst = Uav(TEXT("t12"));
        P->params = Raw(10);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p10_conv"), TShaderMapRef<Fp10_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t12")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t12")).Y, 8), 8));
    }
    {  // p11_resize_linear: Resize
        auto* P = GraphBuilder.AllocParameters<Fp11_resize_linear::FParameters>();
        P->src0 = Srv(TEXT("t12"));
        P->dst = Uav(TEXT("t13"));
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p11_resize_linear"), TShaderMapRef<Fp11_resize_linear>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t13")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t13")).Y, 8), 8));
    }
    {  // p12_conv: Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp12_conv::FParameters>();
        P->src0 = Srv(TEXT("t13"));
        P->dst = Uav(TEXT("t14"));
        P->params = Raw(12);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p12_conv"), TShaderMapRef<Fp12_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t14")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t14")).Y, 8), 4));
    }
    {  // p13_conv: Concat + Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp13_conv::FParameters>();
        P->src0 = Srv(TEXT("t14"));
        P->src1 = Srv(TEXT("t10"));
        P->dst = Uav(TEXT("t15"));
        P->params = Raw(13);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p13_conv"), TShaderMapRef<Fp13_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t15")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t15")).Y, 8), 4));
    }
    {  // p14_resize_linear: Resize
        auto* P = GraphBuilder.AllocParameters<Fp14_resize_linear::FParameters>();
        P->src0 = Srv(TEXT("t15"));
        P->dst = Uav(TEXT("t16"));
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p14_resize_linear"), TShaderMapRef<Fp14_resize_linear>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t16")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t16")).Y, 8), 4));
    }
    {  // p15_conv: Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp15_conv::FParameters>();
        P->src0 = Srv(TEXT("t16"));
        P->dst = Uav(TEXT("t17"));
        P->params = Raw(15);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p15_conv"), TShaderMapRef<Fp15_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t17")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t17")).Y, 8), 2));
    }
    {  // p16_conv: Concat + Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp16_conv::FParameters>();
        P->src0 = Srv(TEXT("t17"));
        P->src1 = Srv(TEXT("t8"));
        P->dst = Uav(TEXT("t18"));
        P->params = Raw(16);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p16_conv"), TShaderMapRef<Fp16_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t18")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t18")).Y, 8), 2));
    }
    {  // p17_resize_linear: Resize
        auto* P = GraphBuilder.AllocParameters<Fp17_resize_linear::FParameters>();
        P->src0 = Srv(TEXT("t18"));
        P->dst = Uav(TEXT("t19"));
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p17_resize_linear"), TShaderMapRef<Fp17_resize_linear>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t19")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t19")).Y, 8), 2));
    }
    {  // p18_conv: Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp18_conv::FParameters>();
        P->src0 = Srv(TEXT("t19"));
        P->dst = Uav(TEXT("t20"));
        P->params = Raw(18);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p18_conv"), TShaderMapRef<Fp18_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t20")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t20")).Y, 8), 1));
    }
    {  // p19_conv: Concat + Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp19_conv::FParameters>();
        P->src0 = Srv(TEXT("t20"));
        P->src1 = Srv(TEXT("t6"));
        P->dst = Uav(TEXT("t21"));
        P->params = Raw(19);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p19_conv"), TShaderMapRef<Fp19_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t21")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t21")).Y, 8), 1));
    }
    {  // p20_conv: Conv + Add + Clip + Crop
        auto* P = GraphBuilder.AllocParameters<Fp20_conv::FParameters>();
        P->src0 = Srv(TEXT("t21"));
        P->src1 = Srv(TEXT("t5"));
        P->dst = Uav(TEXT("t24"));
        P->params = Raw(20);
        P->u_flip_y = bFlipY ? 1 : 0;
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p20_conv"), TShaderMapRef<Fp20_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t24")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t24")).Y, 8), 1));
    }
}
}  // namespace NeuralAOUnetGtao
