// Generated from the manifests of unet-gtao by `python -m neuralao.export.glsl.engines`; tests/test_engine_wrappers.py checks it against the manifests and the exported shaders.
// Not run here (no Unreal): the HLSL these classes bind, by these names and registers, runs the whole
// frame on Vulkan (lavapipe) in tests/test_frame_passes.py.
#pragma once

#include "GlobalShader.h"
#include "RenderGraphBuilder.h"
#include "ShaderParameterStruct.h"

namespace NeuralAOUnetGtao
{
constexpr int32 PadMultiple = 8;
constexpr int32 InternalHeight = 256;  // network rows; 0: the network runs at W x H

/** The frame passes' cbuffer FrameUniforms (b0), members at the HLSL's offsets (32 bytes). */
BEGIN_GLOBAL_SHADER_PARAMETER_STRUCT(FFrameUniforms, )
    SHADER_PARAMETER(FVector2f, frame_u_proj)  // offset 0
    SHADER_PARAMETER(float, frame_u_radius)  // offset 8
    SHADER_PARAMETER(float, frame_u_pixels_per_unit)  // offset 12
    SHADER_PARAMETER(int32, frame_u_flip_y)  // offset 16
END_GLOBAL_SHADER_PARAMETER_STRUCT()

class Ff_gtao : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Ff_gtao);
    SHADER_USE_PARAMETER_STRUCT(Ff_gtao, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src1)  // t1
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float>, dst)  // u0
        SHADER_PARAMETER_RDG_UNIFORM_BUFFER(FFrameUniforms, FrameUniforms)  // b0
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 0);
    }
};

class Ff_gtao_blur : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Ff_gtao_blur);
    SHADER_USE_PARAMETER_STRUCT(Ff_gtao_blur, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src1)  // t1
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float>, dst)  // u0
        SHADER_PARAMETER_RDG_UNIFORM_BUFFER(FFrameUniforms, FrameUniforms)  // b0
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 1);
    }
};

class Ff_downsample : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Ff_downsample);
    SHADER_USE_PARAMETER_STRUCT(Ff_downsample, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src1)  // t1
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src2)  // t2
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src3)  // t3
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER_RDG_UNIFORM_BUFFER(FFrameUniforms, FrameUniforms)  // b0
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 2);
    }
};

class Ff_network_input : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Ff_network_input);
    SHADER_USE_PARAMETER_STRUCT(Ff_network_input, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER_RDG_UNIFORM_BUFFER(FFrameUniforms, FrameUniforms)  // b0
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 3);
    }
};

class Ff_network_radius : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Ff_network_radius);
    SHADER_USE_PARAMETER_STRUCT(Ff_network_radius, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER_RDG_UNIFORM_BUFFER(FFrameUniforms, FrameUniforms)  // b0
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 4);
    }
};

class Fp01_pointwise : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp01_pointwise);
    SHADER_USE_PARAMETER_STRUCT(Fp01_pointwise, FGlobalShader);
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
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 5);
    }
};

class Fp02_pointwise : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp02_pointwise);
    SHADER_USE_PARAMETER_STRUCT(Fp02_pointwise, FGlobalShader);
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
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 6);
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
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 7);
    }
};

class Fp04_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp04_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp04_conv, FGlobalShader);
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

class Fp05_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp05_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp05_conv, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER_RDG_BUFFER_SRV(ByteAddressBuffer, params)  // t16
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 9);
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
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 10);
    }
};

class Fp07_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp07_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp07_conv, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER_RDG_BUFFER_SRV(ByteAddressBuffer, params)  // t16
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 11);
    }
};

class Fp08_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp08_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp08_conv, FGlobalShader);
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
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 12);
    }
};

class Fp09_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp09_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp09_conv, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
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

class Fp10_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp10_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp10_conv, FGlobalShader);
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
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 14);
    }
};

class Fp11_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp11_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp11_conv, FGlobalShader);
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

class Fp12_conv : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp12_conv);
    SHADER_USE_PARAMETER_STRUCT(Fp12_conv, FGlobalShader);
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

class Fp13_pointwise : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Fp13_pointwise);
    SHADER_USE_PARAMETER_STRUCT(Fp13_pointwise, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src1)  // t1
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src2)  // t2
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float4>, dst)  // u0
        SHADER_PARAMETER_RDG_BUFFER_SRV(ByteAddressBuffer, params)  // t16
        SHADER_PARAMETER(int32, u_flip_y)  // $Globals
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 17);
    }
};

class Ff_upsample : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Ff_upsample);
    SHADER_USE_PARAMETER_STRUCT(Ff_upsample, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src1)  // t1
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src2)  // t2
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src3)  // t3
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src4)  // t4
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float>, dst)  // u0
        SHADER_PARAMETER_RDG_UNIFORM_BUFFER(FFrameUniforms, FrameUniforms)  // b0
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 18);
    }
};

class Ff_composite : public FGlobalShader
{
public:
    DECLARE_GLOBAL_SHADER(Ff_composite);
    SHADER_USE_PARAMETER_STRUCT(Ff_composite, FGlobalShader);
    BEGIN_SHADER_PARAMETER_STRUCT(FParameters, )
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src0)  // t0
        SHADER_PARAMETER_RDG_TEXTURE_SRV(Texture2DArray<float4>, src1)  // t1
        SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<float>, dst)  // u0
        SHADER_PARAMETER_RDG_UNIFORM_BUFFER(FFrameUniforms, FrameUniforms)  // b0
    END_SHADER_PARAMETER_STRUCT()
    static void ModifyCompilationEnvironment(const FGlobalShaderPermutationParameters& Parameters,
                                             FShaderCompilerEnvironment& OutEnvironment)
    {
        FGlobalShader::ModifyCompilationEnvironment(Parameters, OutEnvironment);
        OutEnvironment.SetDefine(TEXT("NEURALAO_PASS"), 19);
    }
};

/** The frame's textures (CreateTextures) and the per-pass weight buffers (each made with
 * FRDGBufferDesc::CreateByteAddressDesc(bytes), filled with the pass's range of weights.bin). */
struct FResources
{
    TMap<FString, FRDGTextureRef> Textures;
    TMap<int32, FRDGBufferRef> Weights;
};

/** Every texture of the frame (frame.textures) for a Frame.X x Frame.Y frame. Before AddPasses, write the
 * inputs:
 *  depth: write each frame: linear depth -z_cam in scene units (lane 0), 0 on background; the passes reconstruct camera-space positions from it, the pixel and u_proj
 *  normal: write each frame: camera-space unit normal (xyz), OpenGL axes, facing the viewer
 */
TMap<FString, FRDGTextureRef> CreateTextures(FRDGBuilder& GraphBuilder, FIntPoint Frame);

/** Every step of the frame in order (RDG orders the dispatches by their texture reads and writes);
 * Projection: the view's projection matrix. Returns the AO texture "ao". */
FRDGTextureRef AddPasses(FRDGBuilder& GraphBuilder, const FResources& R, FIntPoint Frame, const FMatrix& Projection, float Radius);
}  // namespace NeuralAOUnetGtao
