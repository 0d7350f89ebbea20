// Generated from the manifests of unet-gtao by `python -m neuralao.export.glsl.engines`; tests/test_engine_wrappers.py checks it against the manifests and the exported shaders.
#include "NeuralAOUnetGtao.h"

#include "RenderGraphUtils.h"

namespace NeuralAOUnetGtao
{
IMPLEMENT_GLOBAL_SHADER_PARAMETER_STRUCT(FFrameUniforms, "FrameUniforms");
IMPLEMENT_GLOBAL_SHADER(Ff_gtao, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "f_gtao", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Ff_gtao_blur, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "f_gtao_blur", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Ff_downsample, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "f_downsample", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Ff_network_input, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "f_network_input", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Ff_network_radius, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "f_network_radius", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp01_pointwise, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p01_pointwise", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp02_pointwise, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p02_pointwise", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp03_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p03_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp04_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p04_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp05_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p05_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp06_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p06_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp07_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p07_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp08_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p08_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp09_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p09_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp10_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p10_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp11_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p11_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp12_conv, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p12_conv", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Fp13_pointwise, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "p13_pointwise", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Ff_upsample, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "f_upsample", SF_Compute);
IMPLEMENT_GLOBAL_SHADER(Ff_composite, "/Plugin/NeuralAO/NeuralAOUnetGtao.usf", "f_composite", SF_Compute);

TMap<FString, FRDGTextureRef> CreateTextures(FRDGBuilder& GraphBuilder, FIntPoint Frame)
{
    const int32 W = Frame.X, H = Frame.Y;
    const int32 w = InternalHeight > 0 ? FMath::Max(1, (int32)FMath::RoundHalfToEven((double)W * InternalHeight / H)) : W;
    const int32 h = InternalHeight > 0 ? InternalHeight : H;
    const int32 wp = FMath::DivideAndRoundUp(w, PadMultiple) * PadMultiple, hp = FMath::DivideAndRoundUp(h, PadMultiple) * PadMultiple;
    TMap<FString, FRDGTextureRef> T;
    auto Make = [&](const TCHAR* Id, int32 X, int32 Y, int32 Layers, EPixelFormat Format) {
        T.Add(Id, GraphBuilder.CreateTexture(FRDGTextureDesc::Create2DArray(FIntPoint(X, Y), Format, FClearValueBinding::None,
            TexCreate_ShaderResource | TexCreate_UAV, Layers), Id));
    };
    Make(TEXT("ao"), W, H, 1, PF_R32_FLOAT);
    Make(TEXT("depth"), W, H, 1, PF_R32_FLOAT);
    Make(TEXT("gtao"), W, H, 1, PF_R32_FLOAT);
    Make(TEXT("gtao_raw"), W, H, 1, PF_R32_FLOAT);
    Make(TEXT("low_gbuffer"), w, h, 3, PF_A32B32G32R32F);
    Make(TEXT("normal"), W, H, 1, PF_A32B32G32R32F);
    Make(TEXT("t0"), w, h, 2, PF_A32B32G32R32F);
    Make(TEXT("t12"), wp, hp, 2, PF_A32B32G32R32F);
    Make(TEXT("t14"), wp, hp, 1, PF_A32B32G32R32F);
    Make(TEXT("t16"), wp * 1 / 2, hp * 1 / 2, 2, PF_A32B32G32R32F);
    Make(TEXT("t18"), wp * 1 / 4, hp * 1 / 4, 4, PF_A32B32G32R32F);
    Make(TEXT("t2"), 1, 1, 1, PF_A32B32G32R32F);
    Make(TEXT("t20"), wp * 1 / 8, hp * 1 / 8, 8, PF_A32B32G32R32F);
    Make(TEXT("t22"), wp * 1 / 4, hp * 1 / 4, 4, PF_A32B32G32R32F);
    Make(TEXT("t23"), wp * 1 / 4, hp * 1 / 4, 4, PF_A32B32G32R32F);
    Make(TEXT("t25"), wp * 1 / 2, hp * 1 / 2, 2, PF_A32B32G32R32F);
    Make(TEXT("t26"), wp * 1 / 2, hp * 1 / 2, 2, PF_A32B32G32R32F);
    Make(TEXT("t28"), wp, hp, 1, PF_A32B32G32R32F);
    Make(TEXT("t29"), wp, hp, 1, PF_A32B32G32R32F);
    Make(TEXT("t32"), w, h, 1, PF_A32B32G32R32F);
    Make(TEXT("t9"), wp, hp, 1, PF_A32B32G32R32F);
    return T;
}

FRDGTextureRef AddPasses(FRDGBuilder& GraphBuilder, const FResources& R, FIntPoint Frame, const FMatrix& Projection, float Radius)
{
    FGlobalShaderMap* ShaderMap = GetGlobalShaderMap(GMaxRHIFeatureLevel);
    auto Srv = [&](const TCHAR* T) { return GraphBuilder.CreateSRV(FRDGTextureSRVDesc::Create(R.Textures[T])); };
    auto Uav = [&](const TCHAR* T) { return GraphBuilder.CreateUAV(FRDGTextureUAVDesc(R.Textures[T])); };
    auto Raw = [&](int32 Pass) { return GraphBuilder.CreateSRV(R.Weights[Pass]); };
    auto Size = [&](const TCHAR* T) { return R.Textures[T]->Desc.Extent; };
    const float p00 = Projection.M[0][0], p11 = Projection.M[1][1];
    const float radius = Radius;
    const float pixels_per_unit = 0.5f * Frame.Y * p11;
    const int32 flip = 0;  // row 0 is the top row on every RHI Unreal renders with (D3D, Vulkan, Metal)
    const bool bSameSize = Size(TEXT("t0")) == Frame;  // the steps marked (w, h) == (W, H) run
    auto* U = GraphBuilder.AllocParameters<FFrameUniforms>();
    U->frame_u_proj = FVector2f(p00, p11);
    U->frame_u_radius = radius;
    U->frame_u_pixels_per_unit = pixels_per_unit;
    U->frame_u_flip_y = flip;
    TRDGUniformBufferRef<FFrameUniforms> FrameUniformBuffer = GraphBuilder.CreateUniformBuffer(U);
    {  // step 0: f_gtao: GTAO, 4 slices x 8 steps per side
        auto* P = GraphBuilder.AllocParameters<Ff_gtao::FParameters>();
        P->src0 = Srv(TEXT("depth"));
        P->src1 = Srv(TEXT("normal"));
        P->dst = Uav(TEXT("gtao_raw"));
        P->FrameUniforms = FrameUniformBuffer;
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("f_gtao"), TShaderMapRef<Ff_gtao>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("gtao_raw")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("gtao_raw")).Y, 8), 1));
    }
    {  // step 1: f_gtao_blur: GTAO's 4x4 foreground-only blur
        auto* P = GraphBuilder.AllocParameters<Ff_gtao_blur::FParameters>();
        P->src0 = Srv(TEXT("depth"));
        P->src1 = Srv(TEXT("gtao_raw"));
        P->dst = Uav(TEXT("gtao"));
        P->FrameUniforms = FrameUniformBuffer;
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("f_gtao_blur"), TShaderMapRef<Ff_gtao_blur>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("gtao")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("gtao")).Y, 8), 1));
    }
    {  // step 2: f_downsample: point sampling to the network's size, position from depth, GTAO
        auto* P = GraphBuilder.AllocParameters<Ff_downsample::FParameters>();
        P->src0 = Srv(TEXT("depth"));
        P->src1 = Srv(TEXT("normal"));
        P->src2 = Srv(TEXT("gtao"));
        P->src3 = Srv(TEXT("gtao_raw"));
        P->dst = Uav(TEXT("low_gbuffer"));
        P->FrameUniforms = FrameUniformBuffer;
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("f_downsample"), TShaderMapRef<Ff_downsample>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("low_gbuffer")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("low_gbuffer")).Y, 8), 1));
    }
    {  // step 3: f_network_input: the network's input: log depth, normal, GTAO
        auto* P = GraphBuilder.AllocParameters<Ff_network_input::FParameters>();
        P->src0 = Srv(TEXT("low_gbuffer"));
        P->dst = Uav(TEXT("t0"));
        P->FrameUniforms = FrameUniformBuffer;
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("f_network_input"), TShaderMapRef<Ff_network_input>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t0")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t0")).Y, 8), 1));
    }
    {  // step 4: f_network_radius: the network's radius input log(R P11)
        auto* P = GraphBuilder.AllocParameters<Ff_network_radius::FParameters>();
        P->dst = Uav(TEXT("t2"));
        P->FrameUniforms = FrameUniformBuffer;
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("f_network_radius"), TShaderMapRef<Ff_network_radius>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t2")).X, 1), FMath::DivideAndRoundUp(Size(TEXT("t2")).Y, 1), 1));
    }
    // step 5: p00_uniform skipped: f_network_radius writes its texture
    {  // step 6: p01_pointwise: Pad + Mul + Conv + Mul + Clip + Conv + Sub + Mul + Neg + Exp + Clip + Mul
        auto* P = GraphBuilder.AllocParameters<Fp01_pointwise::FParameters>();
        P->src0 = Srv(TEXT("t0"));
        P->src1 = Srv(TEXT("t2"));
        P->dst = Uav(TEXT("t9"));
        P->params = Raw(1);
        P->u_flip_y = flip;
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p01_pointwise"), TShaderMapRef<Fp01_pointwise>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t9")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t9")).Y, 8), 1));
    }
    {  // step 7: p02_pointwise: Pad + Mul + Conv + Mul + Clip + Conv + Sub + Mul + Sub + Conv + Add
        auto* P = GraphBuilder.AllocParameters<Fp02_pointwise::FParameters>();
        P->src0 = Srv(TEXT("t0"));
        P->src1 = Srv(TEXT("t2"));
        P->dst = Uav(TEXT("t12"));
        P->params = Raw(2);
        P->u_flip_y = flip;
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p02_pointwise"), TShaderMapRef<Fp02_pointwise>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t12")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t12")).Y, 8), 2));
    }
    {  // step 8: p03_conv: Concat + Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp03_conv::FParameters>();
        P->src0 = Srv(TEXT("t12"));
        P->src1 = Srv(TEXT("t9"));
        P->dst = Uav(TEXT("t14"));
        P->params = Raw(3);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p03_conv"), TShaderMapRef<Fp03_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t14")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t14")).Y, 8), 1));
    }
    {  // step 9: p04_conv: AveragePool + Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp04_conv::FParameters>();
        P->src0 = Srv(TEXT("t14"));
        P->dst = Uav(TEXT("t16"));
        P->params = Raw(4);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p04_conv"), TShaderMapRef<Fp04_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t16")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t16")).Y, 8), 2));
    }
    {  // step 10: p05_conv: AveragePool + Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp05_conv::FParameters>();
        P->src0 = Srv(TEXT("t16"));
        P->dst = Uav(TEXT("t18"));
        P->params = Raw(5);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p05_conv"), TShaderMapRef<Fp05_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t18")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t18")).Y, 8), 4));
    }
    {  // step 11: p06_conv: AveragePool + Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp06_conv::FParameters>();
        P->src0 = Srv(TEXT("t18"));
        P->dst = Uav(TEXT("t20"));
        P->params = Raw(6);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p06_conv"), TShaderMapRef<Fp06_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t20")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t20")).Y, 8), 8));
    }
    {  // step 12: p07_conv: Resize + Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp07_conv::FParameters>();
        P->src0 = Srv(TEXT("t20"));
        P->dst = Uav(TEXT("t22"));
        P->params = Raw(7);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p07_conv"), TShaderMapRef<Fp07_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t22")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t22")).Y, 8), 4));
    }
    {  // step 13: p08_conv: Concat + Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp08_conv::FParameters>();
        P->src0 = Srv(TEXT("t22"));
        P->src1 = Srv(TEXT("t18"));
        P->dst = Uav(TEXT("t23"));
        P->params = Raw(8);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p08_conv"), TShaderMapRef<Fp08_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t23")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t23")).Y, 8), 4));
    }
    {  // step 14: p09_conv: Resize + Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp09_conv::FParameters>();
        P->src0 = Srv(TEXT("t23"));
        P->dst = Uav(TEXT("t25"));
        P->params = Raw(9);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p09_conv"), TShaderMapRef<Fp09_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t25")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t25")).Y, 8), 2));
    }
    {  // step 15: p10_conv: Concat + Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp10_conv::FParameters>();
        P->src0 = Srv(TEXT("t25"));
        P->src1 = Srv(TEXT("t16"));
        P->dst = Uav(TEXT("t26"));
        P->params = Raw(10);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p10_conv"), TShaderMapRef<Fp10_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t26")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t26")).Y, 8), 2));
    }
    {  // step 16: p11_conv: Resize + Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp11_conv::FParameters>();
        P->src0 = Srv(TEXT("t26"));
        P->dst = Uav(TEXT("t28"));
        P->params = Raw(11);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p11_conv"), TShaderMapRef<Fp11_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t28")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t28")).Y, 8), 1));
    }
    {  // step 17: p12_conv: Concat + Conv + LeakyRelu
        auto* P = GraphBuilder.AllocParameters<Fp12_conv::FParameters>();
        P->src0 = Srv(TEXT("t28"));
        P->src1 = Srv(TEXT("t14"));
        P->dst = Uav(TEXT("t29"));
        P->params = Raw(12);
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p12_conv"), TShaderMapRef<Fp12_conv>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t29")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t29")).Y, 8), 1));
    }
    {  // step 18: p13_pointwise: Concat + Conv + Conv + Add + Clip + Crop
        auto* P = GraphBuilder.AllocParameters<Fp13_pointwise::FParameters>();
        P->src0 = Srv(TEXT("t12"));
        P->src1 = Srv(TEXT("t9"));
        P->src2 = Srv(TEXT("t29"));
        P->dst = Uav(TEXT("t32"));
        P->params = Raw(13);
        P->u_flip_y = flip;
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("p13_pointwise"), TShaderMapRef<Fp13_pointwise>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("t32")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("t32")).Y, 8), 1));
    }
    if (!bSameSize)  // (w, h) != (W, H)
    {  // step 19: f_upsample: joint bilateral upsampling of the correction to GTAO, added to GTAO and clamped
        auto* P = GraphBuilder.AllocParameters<Ff_upsample::FParameters>();
        P->src0 = Srv(TEXT("depth"));
        P->src1 = Srv(TEXT("normal"));
        P->src2 = Srv(TEXT("t32"));
        P->src3 = Srv(TEXT("low_gbuffer"));
        P->src4 = Srv(TEXT("gtao"));
        P->dst = Uav(TEXT("ao"));
        P->FrameUniforms = FrameUniformBuffer;
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("f_upsample"), TShaderMapRef<Ff_upsample>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("ao")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("ao")).Y, 8), 1));
    }
    if (bSameSize)  // (w, h) == (W, H)
    {  // step 20: f_composite: the network's AO, 1 on background
        auto* P = GraphBuilder.AllocParameters<Ff_composite::FParameters>();
        P->src0 = Srv(TEXT("depth"));
        P->src1 = Srv(TEXT("t32"));
        P->dst = Uav(TEXT("ao"));
        P->FrameUniforms = FrameUniformBuffer;
        FComputeShaderUtils::AddPass(GraphBuilder, RDG_EVENT_NAME("f_composite"), TShaderMapRef<Ff_composite>(ShaderMap), P,
            FIntVector(FMath::DivideAndRoundUp(Size(TEXT("ao")).X, 8), FMath::DivideAndRoundUp(Size(TEXT("ao")).Y, 8), 1));
    }
    return R.Textures[TEXT("ao")];
}
}  // namespace NeuralAOUnetGtao
