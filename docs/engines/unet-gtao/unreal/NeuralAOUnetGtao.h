// Generated from the manifest of unet-gtao by `python -m neuralao.export.glsl.engines`; tests/test_engine_wrappers.py checks it against the manifest and the generated shaders.
// Not run here (no Unreal): the HLSL these classes bind, by these names, runs on Vulkan in
// tests/test_hlsl_target.py.
#pragma once

#include "GlobalShader.h"
#include "RenderGraphBuilder.h"
#include "ShaderParameterStruct.h"

namespace NeuralAOUnetGtao
{
constexpr int32 PadMultiple = 8;

class Fp00_pad : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp00_pad);
    SHADER_USE_PARAMETER_STRUCT(Fp00_pad, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER(int32, u_flip_y)  // $Globals
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 0);
    }
};

class Fp01_uniform : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp01_uniform);
    SHADER_USE_PARAMETER_STRUCT(Fp01_uniform, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER(float, u_radius)  // $Globals
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 1);
    }
};

class Fp02_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp02_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp02_conv, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src1)  // t1
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER_RDG_BUFFER_SRV(ByteAddressBuffer, params)  // t16
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 2);
    }
};

class Fp03_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp03_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp03_conv, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src1)  // t1
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER_RDG_BUFFER_SRV(ByteAddressBuffer, params)  // t16
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 3);
    }
};

class Fp04_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp04_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp04_conv, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src1)  // t1
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER_RDG_BUFFER_SRV(ByteAddressBuffer, params)  // t16
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 4);
    }
};

class Fp05_pool_avg : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp05_pool_avg);
    SHADER_USE_PARAMETER_STRUCT(Fp05_pool_avg, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 5);
    }
};

class Fp06_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp06_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp06_conv, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER_RDG_BUFFER_SRV(ByteAddressBuffer, params)  // t16
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 6);
    }
};

class Fp07_pool_avg : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp07_pool_avg);
    SHADER_USE_PARAMETER_STRUCT(Fp07_pool_avg, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 7);
    }
};

class Fp08_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp08_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp08_conv, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER_RDG_BUFFER_SRV(ByteAddressBuffer, params)  // t16
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 8);
    }
};

class Fp09_pool_avg : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp09_pool_avg);
    SHADER_USE_PARAMETER_STRUCT(Fp09_pool_avg, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 9);
    }
};

class Fp10_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp10_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp10_conv, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER_RDG_BUFFER_SRV(ByteAddressBuffer, params)  // t16
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 10);
    }
};

class Fp11_resize_linear : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp11_resize_linear);
    SHADER_USE_PARAMETER_STRUCT(Fp11_resize_linear, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 11);
    }
};

class Fp12_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp12_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp12_conv, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER_RDG_BUFFER_SRV(ByteAddressBuffer, params)  // t16
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 12);
    }
};

class Fp13_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp13_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp13_conv, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src1)  // t1
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER_RDG_BUFFER_SRV(ByteAddressBuffer, params)  // t16
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 13);
    }
};

class Fp14_resize_linear : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp14_resize_linear);
    SHADER_USE_PARAMETER_STRUCT(Fp14_resize_linear, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 14);
    }
};

class Fp15_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp15_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp15_conv, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER_RDG_BUFFER_SRV(ByteAddressBuffer, params)  // t16
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 15);
    }
};

class Fp16_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp16_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp16_conv, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src1)  // t1
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER_RDG_BUFFER_SRV(ByteAddressBuffer, params)  // t16
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 16);
    }
};

class Fp17_resize_linear : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp17_resize_linear);
    SHADER_USE_PARAMETER_STRUCT(Fp17_resize_linear, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 17);
    }
};

class Fp18_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp18_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp18_conv, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER_RDG_BUFFER_SRV(ByteAddressBuffer, params)  // t16
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 18);
    }
};

class Fp19_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp19_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp19_conv, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src1)  // t1
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER_RDG_BUFFER_SRV(ByteAddressBuffer, params)  // t16
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 19);
    }
};

class Fp20_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp20_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp20_conv, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src1)  // t1
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER_RDG_BUFFER_SRV(ByteAddressBuffer, params)  // t16
        SHADER_PARAMETER(int32, u_flip_y)  // $Globals
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 20);
    }
};

/** The textures (t0 the input, t24 the output) and per-pass weight buffers of one frame size. */
struct FResources
{
    TMap<FString, FRDGTextureRef> Textures;
    TMap<int32, FRDGBufferRef> Weights;  // a buffer per pass with params: its range of weights.bin
};

/** Every pass in order (RDG orders the dispatches by their texture reads and writes). */
void AddPasses(FRDGBuilder& GraphBuilder, const FResources& R, float u_radius, bool bFlipY);
}  // namespace NeuralAOUnetGtao
