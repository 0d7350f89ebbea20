/*
 * neuralao_host: the reference engine integration of a shipped screen-space AO export, in C.
 *
 *   neuralao_host EXPORT_DIR GBUFFER.f32 WIDTH HEIGHT RADIUS YFOV_DEG OUT.f32
 *
 * EXPORT_DIR   a shipped export (runtime/models/<name>, holding glsl/manifest.json) or its glsl/ folder
 * GBUFFER.f32  raw float32 little-endian, HEIGHT x WIDTH pixels, row 0 = the top row, 5 floats a pixel:
 *              linear camera-space depth z (> 0 in front of the camera, 0 on background),
 *              camera-space unit normal nx, ny, nz (OpenGL axes, facing the viewer), mask (>= 0.5 foreground)
 * RADIUS       AO radius in scene units; YFOV_DEG the vertical field of view in degrees
 * OUT.f32      raw float32, HEIGHT x WIDTH, row 0 = the top row: AO in [0, 1], 1 on background
 *
 * An export whose glsl/manifest.json has a "frame" section (the shipped ones) runs its whole frame on the
 * GPU as the section's "steps" list it (docs/engine-integration.md), with no CPU work between passes:
 *   1. every texture of frame.textures allocated (2-D arrays) at its size formula: W x H the frame,
 *      w x h the network's input (max(1, round(W * internal_height / H)) x internal_height, or W x H when
 *      the export has no internal height), wp x hp those rounded up to the pad multiple;
 *   2. the engine's two inputs uploaded: "depth" (depth on foreground, 0 on background) and "normal"
 *      (the unit normal on foreground, 0 on background), row 0 = the top row;
 *   3. the FrameUniforms block (frame.uniform_block) filled from the camera: u_proj = (P00, P11),
 *      u_radius = RADIUS, u_pixels_per_unit = 0.5 * H * P11, u_flip_y = 0 (textures top row first);
 *   4. each step in order (those marked "skip" left out, of those with a "when" the one whose condition
 *      holds): a frame pass (frame.passes) or a network pass (the manifest's passes[index]), its input
 *      textures, output image, uniform block and weight range bound at their bindings, its groups
 *      dispatched, a memory barrier; the network's pad and crop passes get u_flip_y = 0;
 *   5. only the output texture (frame.output, the AO) read back.
 *
 * An export without a frame section runs the older way, with CPU work around the network's passes, by
 * the input contract its ONNX metadata names (source_model_metadata.preprocess_version):
 *   version 3: t0 = (log z, n) on foreground, 0 on background; rho = log(R / tan(yfov / 2));
 *   version 2: the mean foreground depth m (on the CPU, in double); t0 = (z / m, n); rho = R / (m tan(yfov / 2));
 *   then every texture of the manifest at its size formula, the passes in order, the output read back,
 *   background set to 1. If EXPORT_DIR/manifest.json declares "internal_resolution", the fragment passes
 *   it names run around the network: for a hybrid first GTAO (gtao.frag, its blur) at W x H, then point
 *   sampling to the internal size, the network there (GTAO point-sampled as its fifth channel), upsampling
 *   back to W x H, and for a hybrid AO = clamp(GTAO + upsampled correction, 0, 1).
 *
 * Timing (bench/gpu.sh): with NEURALAO_HOST_REPEATS=N set, after the frame N timed runs of the whole frame
 * (every step), of its GTAO steps (f_gtao, f_gtao_blur; a hybrid's) and of its network steps, each between
 * GL_TIME_ELAPSED queries and on the wall clock between glFinish calls (Mesa's llvmpipe reports 0 GPU time
 * for compute). With NEURALAO_HOST_PROFILE=1 too, each step is timed alone and printed on stderr, a line a
 * step. When EXPORT_DIR/manifest.json has an "ssao" entry (the screen-space AO baseline's fragment
 * passes, written by bench/gpu.sh prepare), SSAO runs N timed times on the same G-buffer too. One JSON line
 * goes to stdout, medians in ms (-1: not run): {"renderer", "version", "width", "height", "repeats", "path",
 * "frame_ms", "network_ms", "gtao_ms", "ssao_ms", the same with _wall_ms, "passes"}. With
 * NEURALAO_HOST_SSAO_OUT=PATH set, that SSAO's AO is written to PATH as OUT.f32 is (what tests check it by).
 * GBUFFER.f32 may be the word "synthetic": a seeded wavy surface filling the frame (all foreground).
 *
 * Context: EGL without a window system (Mesa's surfaceless platform, else an EGL device: NVIDIA's EGL through
 * glvnd), OpenGL 4.3 core.
 * The manifest is read by the small JSON reader of host_common.h (shared with the Vulkan runner, neuralao_vk.c).
 */
#define _POSIX_C_SOURCE 200809L /* clock_gettime */
#define GL_GLEXT_PROTOTYPES 1
#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GL/glcorearb.h>

#define HOST_NAME "neuralao_host"
#include "host_common.h"

/* ------------------------------------------------------------------ GPU timing */

static int g_repeats = 0; /* NEURALAO_HOST_REPEATS: timed runs after the frame */
/* medians of the timed runs (GL_TIME_ELAPSED); -1: not timed */
static double g_frame_ms = -1, g_network_ms = -1, g_gtao_ms = -1, g_ssao_ms = -1;
/* the same runs on the wall clock between glFinish calls: Mesa's llvmpipe reports 0 GPU time for compute */
static double g_frame_wall_ms = -1, g_network_wall_ms = -1, g_gtao_wall_ms = -1, g_ssao_wall_ms = -1;
static double g_wall_start;

static GLuint g_query;

static void time_begin(void) {
    if (!g_query) glGenQueries(1, &g_query);
    glFinish();
    g_wall_start = wall_ms();
    glBeginQuery(GL_TIME_ELAPSED, g_query);
}

/* GPU ms of the run since time_begin; *wall: its wall-clock ms */
static double time_end_ms(double *wall) {
    glEndQuery(GL_TIME_ELAPSED);
    glFinish();
    *wall = wall_ms() - g_wall_start;
    GLuint64 ns = 0;
    glGetQueryObjectui64v(g_query, GL_QUERY_RESULT, &ns);
    return (double)ns * 1e-6;
}

/* ------------------------------------------------------------------ GL context */

/* An EGL display with no window system: Mesa's surfaceless platform, else the first EGL device that
 * initializes (NVIDIA's EGL through glvnd offers EGL_EXT_platform_device), else the default display. */
static EGLDisplay egl_display(void) {
    PFNEGLGETPLATFORMDISPLAYEXTPROC get_display =
        (PFNEGLGETPLATFORMDISPLAYEXTPROC)eglGetProcAddress("eglGetPlatformDisplayEXT");
    EGLint major, minor;
    if (get_display) {
        EGLDisplay dpy = get_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, NULL);
        if (dpy != EGL_NO_DISPLAY && eglInitialize(dpy, &major, &minor)) return dpy;
        PFNEGLQUERYDEVICESEXTPROC query_devices =
            (PFNEGLQUERYDEVICESEXTPROC)eglGetProcAddress("eglQueryDevicesEXT");
        EGLDeviceEXT devices[16];
        EGLint n = 0;
        if (query_devices && query_devices(16, devices, &n)) {
            for (EGLint i = 0; i < n; i++) {
                dpy = get_display(EGL_PLATFORM_DEVICE_EXT, devices[i], NULL);
                if (dpy != EGL_NO_DISPLAY && eglInitialize(dpy, &major, &minor)) return dpy;
            }
        }
    }
    EGLDisplay dpy = eglGetDisplay(EGL_DEFAULT_DISPLAY);
    if (dpy != EGL_NO_DISPLAY && eglInitialize(dpy, &major, &minor)) return dpy;
    die("no EGL display without a window system (surfaceless, device or default)");
    return EGL_NO_DISPLAY;
}

static void egl_context(void) {
    EGLDisplay dpy = egl_display();
    if (!eglBindAPI(EGL_OPENGL_API)) die("EGL cannot bind the OpenGL API");
    const EGLint cfg_attr[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_SURFACE_TYPE, EGL_PBUFFER_BIT, EGL_NONE};
    EGLConfig cfg;
    EGLint n = 0;
    if (!eglChooseConfig(dpy, cfg_attr, &cfg, 1, &n) || n < 1) die("no EGL config for OpenGL");
    const EGLint ctx_attr[] = {EGL_CONTEXT_MAJOR_VERSION, 4, EGL_CONTEXT_MINOR_VERSION, 3,
                               EGL_CONTEXT_OPENGL_PROFILE_MASK, EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL_NONE};
    EGLContext ctx = eglCreateContext(dpy, cfg, EGL_NO_CONTEXT, ctx_attr);
    if (ctx == EGL_NO_CONTEXT) die("cannot create an OpenGL 4.3 core context");
    if (!eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx)) die("cannot make the context current");
}

static GLuint compile_compute(const char *src, const char *name) {
    GLuint sh = glCreateShader(GL_COMPUTE_SHADER);
    glShaderSource(sh, 1, &src, NULL);
    glCompileShader(sh);
    GLint ok;
    char log[4096];
    glGetShaderiv(sh, GL_COMPILE_STATUS, &ok);
    if (!ok) glGetShaderInfoLog(sh, sizeof log, NULL, log), die("%s does not compile: %s", name, log);
    GLuint prog = glCreateProgram();
    glAttachShader(prog, sh);
    glLinkProgram(prog);
    glGetProgramiv(prog, GL_LINK_STATUS, &ok);
    if (!ok) glGetProgramInfoLog(prog, sizeof log, NULL, log), die("%s does not link: %s", name, log);
    glDeleteShader(sh);
    return prog;
}

static GLuint compile_pipeline(const char *vertex, const char *fragment, const char *name) {
    GLint ok;
    char log[4096];
    const char *srcs[2] = {vertex, fragment};
    const GLenum kinds[2] = {GL_VERTEX_SHADER, GL_FRAGMENT_SHADER};
    GLuint prog = glCreateProgram();
    for (int i = 0; i < 2; i++) {
        GLuint sh = glCreateShader(kinds[i]);
        glShaderSource(sh, 1, &srcs[i], NULL);
        glCompileShader(sh);
        glGetShaderiv(sh, GL_COMPILE_STATUS, &ok);
        if (!ok) glGetShaderInfoLog(sh, sizeof log, NULL, log), die("%s does not compile: %s", name, log);
        glAttachShader(prog, sh);
        glDeleteShader(sh);
    }
    glLinkProgram(prog);
    glGetProgramiv(prog, GL_LINK_STATUS, &ok);
    if (!ok) glGetProgramInfoLog(prog, sizeof log, NULL, log), die("%s does not link: %s", name, log);
    return prog;
}

/* ------------------------------------------------------------------ textures */

typedef struct {
    const char *id;
    GLuint tex;
    GLenum internal;
    int w, h, layers;
} Texture;

/* A size formula of the manifest: {"of": "W"|"Wp"|"H"|"Hp", "num", "den", "offset"}. */
static int dim_size(const Json *d, int W, int H, int Wp, int Hp) {
    const char *of = jstr(d, "of");
    int base = !strcmp(of, "W") ? W : !strcmp(of, "H") ? H : !strcmp(of, "Wp") ? Wp : !strcmp(of, "Hp") ? Hp : -1;
    if (base < 0) die("manifest: unknown size symbol %s", of);
    long v = (long)base * (long)jnum(d, "num");
    long den = (long)jnum(d, "den");
    if (v % den) die("texture size %s * %ld / %ld is fractional for this frame size", of, (long)jnum(d, "num"), den);
    return (int)(v / den + (long)jnum(d, "offset"));
}

static Texture *find_texture(Texture *t, int n, const char *id) {
    for (int i = 0; i < n; i++) if (!strcmp(t[i].id, id)) return &t[i];
    die("manifest: no texture %s", id);
    return NULL;
}

/* A 2-D texture as the fragment passes use them: nearest, clamped, row 0 = GL row 0 (the bottom). */
static GLuint texture_2d(int w, int h, GLenum internal, GLenum format, const float *data) {
    GLuint t;
    glGenTextures(1, &t);
    glBindTexture(GL_TEXTURE_2D, t);
    glTexStorage2D(GL_TEXTURE_2D, 1, internal, w, h);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    if (data) {
        glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
        glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, w, h, format, GL_FLOAT, data);
    }
    return t;
}

static float *read_2d(GLuint t, int w, int h, GLenum format, int channels) {
    float *out = xmalloc(sizeof(float) * (size_t)channels * (size_t)w * (size_t)h);
    glBindTexture(GL_TEXTURE_2D, t);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glGetTexImage(GL_TEXTURE_2D, 0, format, GL_FLOAT, out);
    return out;
}

/* ------------------------------------------------------------------ the network (generated passes) */

/* Runs the compute export m (in dir) at w x h on planes: `channels` planes of w x h floats, row 0 on top,
 * in the network's input order. Returns lane 0 of the output, w x h, row 0 on top (not composited). */
static float *run_network(const Json *m, const char *dir, int w, int h, const float *planes, int channels,
                          float rho, int *n_passes) {
    char path[4200];
    const int p = (int)jnum(jreq(m, "pad"), "multiple");
    if (w < p || h < p) die("a %dx%d network input is smaller than the pad multiple %d", w, h, p);
    const int Wp = (w + p - 1) / p * p, Hp = (h + p - 1) / p * p;

    /* step 4: every texture at its size formula */
    Json *tex_json = jreq(m, "textures");
    int n_tex = tex_json->n;
    Texture *tex = xmalloc(sizeof(Texture) * (size_t)n_tex);
    for (int i = 0; i < n_tex; i++) {
        Json *t = tex_json->items[i];
        tex[i].id = tex_json->keys[i];
        tex[i].w = dim_size(jreq(t, "width"), w, h, Wp, Hp);
        tex[i].h = dim_size(jreq(t, "height"), w, h, Wp, Hp);
        tex[i].layers = (int)jnum(t, "layers");
        tex[i].internal = !strcmp(jstr(t, "format"), "RGBA16F") ? GL_RGBA16F : GL_RGBA32F;
        glGenTextures(1, &tex[i].tex);
        glBindTexture(GL_TEXTURE_2D_ARRAY, tex[i].tex);
        glTexStorage3D(GL_TEXTURE_2D_ARRAY, 1, tex[i].internal, tex[i].w, tex[i].h, tex[i].layers);
        glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
        glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    }

    /* step 2: the input texture, channel c in lane c % 4 of layer c / 4 */
    Texture *in = find_texture(tex, n_tex, jstr(jreq(m, "input"), "texture"));
    if (in->w != w || in->h != h) die("input texture %s is %dx%d, expected %dx%d", in->id, in->w, in->h, w, h);
    if ((int)jnum(jreq(m, "input"), "channels") != channels || channels > 4 * in->layers)
        die("the export takes %.0f input channels, this host built %d", jnum(jreq(m, "input"), "channels"), channels);
    const size_t px = (size_t)w * (size_t)h;
    float *x = xmalloc(sizeof(float) * 4 * px * (size_t)in->layers);
    for (int c = 0; c < channels; c++)
        for (size_t i = 0; i < px; i++) x[((size_t)(c / 4) * px + i) * 4 + (size_t)(c % 4)] = planes[(size_t)c * px + i];
    glBindTexture(GL_TEXTURE_2D_ARRAY, in->tex);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTexSubImage3D(GL_TEXTURE_2D_ARRAY, 0, 0, 0, 0, w, h, in->layers, GL_RGBA, GL_FLOAT, x);
    free(x);

    /* the weights: one SSBO, each pass binds its range */
    size_t w_bytes;
    char *weights = read_weights(m, dir, &w_bytes);
    GLuint ssbo;
    glGenBuffers(1, &ssbo);
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, ssbo);
    glBufferData(GL_SHADER_STORAGE_BUFFER, (GLsizeiptr)(w_bytes ? w_bytes : 16), weights, GL_STATIC_DRAW);
    free(weights);

    /* step 3 (rho) and 4: the passes, in order (compiled once: timed runs dispatch them again) */
    Json *passes = jreq(m, "passes");
    GLuint *progs = xmalloc(sizeof(GLuint) * (size_t)(passes->n ? passes->n : 1));
    for (int i = 0; i < passes->n; i++) {
        const char *shader = jstr(passes->items[i], "shader");
        snprintf(path, sizeof path, "%s/%s", dir, shader);
        char *src = read_file(path, NULL);
        progs[i] = compile_compute(src, shader);
        free(src);
    }
    double *runs = xmalloc(sizeof(double) * (size_t)(g_repeats + 1) * 2), *walls = runs + g_repeats + 1;
    for (int run = 0; run <= g_repeats; run++) {
    if (run > 0) time_begin();
    for (int i = 0; i < passes->n; i++) {
        Json *ps = passes->items[i];
        const char *kind = jstr(ps, "kind");
        GLuint prog = progs[i];
        glUseProgram(prog);
        Json *inputs = jreq(ps, "inputs");
        for (int k = 0; k < inputs->n; k++) {
            glActiveTexture(GL_TEXTURE0 + (GLenum)jnum(inputs->items[k], "binding"));
            glBindTexture(GL_TEXTURE_2D_ARRAY, find_texture(tex, n_tex, jstr(inputs->items[k], "texture"))->tex);
        }
        Json *out = jreq(ps, "output");
        Texture *o = find_texture(tex, n_tex, jstr(out, "texture"));
        glBindImageTexture((GLuint)jnum(out, "binding"), o->tex, 0, GL_TRUE, 0, GL_WRITE_ONLY, o->internal);
        Json *params = jget(ps, "params");
        if (params)
            glBindBufferRange(GL_SHADER_STORAGE_BUFFER, (GLuint)jnum(params, "binding"), ssbo,
                              (GLintptr)jnum(params, "offset"), (GLsizeiptr)jnum(params, "bytes"));
        Json *uniforms = jget(ps, "uniforms");
        for (int k = 0; uniforms && k < uniforms->n; k++) {
            Json *u = uniforms->items[k];
            if (!strcmp(kind, "uniform")) {  /* a scalar graph input: the radius is the only one here */
                if (strcmp(jstr(u, "onnx_input"), "radius")) die("scalar input %s is not the radius", jstr(u, "onnx_input"));
                glUniform1f((GLint)jnum(u, "location"), rho);
            } else {
                glUniform1i((GLint)jnum(u, "location"), 0);  /* u_flip_y: our textures are top row first */
            }
        }
        Json *ls = jreq(ps, "local_size"), *block = jget(ps, "block");
        int bx = block ? (int)block->items[0]->num : 1, by = block ? (int)block->items[1]->num : 1;
        int bl = block ? (int)block->items[2]->num : 1;
        int lx = (int)ls->items[0]->num, ly = (int)ls->items[1]->num;
        glDispatchCompute((GLuint)((o->w + lx * bx - 1) / (lx * bx)), (GLuint)((o->h + ly * by - 1) / (ly * by)),
                          (GLuint)(o->layers / bl));
        glMemoryBarrier(GL_TEXTURE_FETCH_BARRIER_BIT | GL_SHADER_IMAGE_ACCESS_BARRIER_BIT);
    }
    if (run > 0) runs[run - 1] = time_end_ms(&walls[run - 1]);
    }
    if (g_repeats > 0) g_network_ms = median(runs, g_repeats), g_network_wall_ms = median(walls, g_repeats);
    for (int i = 0; i < passes->n; i++) glDeleteProgram(progs[i]);
    free(progs), free(runs);
    *n_passes = passes->n;

    /* the output: lane 0 of layer 0 of the first output texture */
    Texture *res = find_texture(tex, n_tex, jstr(jreq(m, "outputs")->items[0], "texture"));
    if (res->w != w || res->h != h) die("output texture %s is %dx%d, expected %dx%d", res->id, res->w, res->h, w, h);
    float *rgba = xmalloc(sizeof(float) * 4 * (size_t)res->w * res->h * (size_t)res->layers);
    glBindTexture(GL_TEXTURE_2D_ARRAY, res->tex);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glGetTexImage(GL_TEXTURE_2D_ARRAY, 0, GL_RGBA, GL_FLOAT, rgba);
    float *y = xmalloc(sizeof(float) * px);
    for (size_t i = 0; i < px; i++) y[i] = rgba[i * 4];
    free(rgba);
    for (int i = 0; i < n_tex; i++) glDeleteTextures(1, &tex[i].tex);
    glDeleteBuffers(1, &ssbo);
    free(tex);
    return y;
}

/* Mean foreground depth m (double, as the Python reference): version 2's one statistic of the frame. */
static double mean_depth_of(const float *depth, const float *mask, size_t px) {
    double sum = 0.0;
    long count = 0;
    for (size_t i = 0; i < px; i++)
        if (mask[i] >= 0.5f) sum += depth[i], count++;
    return count ? sum / (double)count : 1.0;
}

/* The input contract of the export (its ONNX metadata's preprocess_version); 2 when it names none. */
static int preprocess_version(const Json *m) {
    const Json *meta = jget(m, "source_model_metadata");
    const Json *v = meta && meta->type == J_OBJ ? jget(meta, "preprocess_version") : NULL;
    if (!v) return 2;
    const int version = v->type == J_STR ? atoi(v->str) : v->type == J_NUM ? (int)v->num : 0;
    if (version != 2 && version != 3) die("the export expects input contract %d; this host runs 2 and 3", version);
    return version;
}

/* Steps 1-3 on a G-buffer of px pixels: the depth plane (log z, or z / m for version 2) on foreground and
 * 0 on background, written to depth_plane; returns rho. */
static float depth_plane_and_rho(int version, const float *depth, const float *mask, size_t px,
                                 double radius, double yfov, float *depth_plane) {
    if (version == 3) {
        for (size_t i = 0; i < px; i++) depth_plane[i] = mask[i] >= 0.5f && depth[i] > 0.0f ? logf(depth[i]) : 0.0f;
        return (float)(log(radius) - log(tan(0.5 * yfov)));
    }
    const double mean = mean_depth_of(depth, mask, px);
    const float m32 = (float)mean;
    for (size_t i = 0; i < px; i++) depth_plane[i] = mask[i] >= 0.5f ? depth[i] / m32 : 0.0f;
    return (float)(radius / (mean * tan(0.5 * yfov)));
}

/* ------------------------------------------------------------------ the internal-resolution passes */

typedef struct {
    GLuint position, normal;  /* full-resolution G-buffer, RGBA32F, GL order */
    GLuint vao;
    const char *vertex;
    int W, H;
} Frame;

static void draw_fullscreen(GLuint prog, GLuint *targets, int n_targets, int w, int h) {
    GLuint fbo;
    glGenFramebuffers(1, &fbo);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    GLenum bufs[4];
    for (int i = 0; i < n_targets; i++) {
        glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0 + (GLenum)i, GL_TEXTURE_2D, targets[i], 0);
        bufs[i] = GL_COLOR_ATTACHMENT0 + (GLenum)i;
    }
    glDrawBuffers(n_targets, bufs);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) die("incomplete framebuffer");
    glViewport(0, 0, w, h);
    glUseProgram(prog);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    glUseProgram(0);
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    glDeleteFramebuffers(1, &fbo);
}

static char *pass_source(const char *folder, const Json *sources, const char *key) {
    char path[4200];
    snprintf(path, sizeof path, "%s/%s", folder, jstr(sources, key));
    return read_file(path, NULL);
}

/* A screen-space AO pass described as neuralao.runtime.baselines describes one (an export's "gtao" entry,
 * the bench's "ssao" entry) at W x H: sources[name] (gtao.frag, ssao.frag), then sources[name + "_blur"] on
 * its output when the description has a blur. Returns the R32F AO texture. A uniform with a "value" is set
 * as given (a number, or a list for an array: vec3 / float by its "type"), one with "times_radius" to that
 * multiple of the radius; the rest are the formulas neuralao.runtime.baselines computes from the frame
 * (u_proj, u_radius, u_pixels_per_unit). With NEURALAO_HOST_REPEATS the passes run that many more times,
 * timed: medians to *ms (GPU) and *wall (wall clock). */
static GLuint run_screen_space(const Frame *f, const char *folder, const Json *sources, const char *name,
                               const Json *g, double radius, double yfov, double *ms, double *wall) {
    Json *noise = jreq(g, "noise"), *texels = jreq(noise, "texels");
    const int nw = (int)jnum(noise, "width"), nh = (int)jnum(noise, "height");
    if (texels->n != nw * nh * 4)
        die("manifest: the %s noise tile has %d values, not %d", name, texels->n, nw * nh * 4);
    float *tile = xmalloc(sizeof(float) * (size_t)texels->n);
    for (int i = 0; i < texels->n; i++) tile[i] = (float)texels->items[i]->num;
    GLuint noise_tex = texture_2d(nw, nh, GL_RGBA32F, GL_RGBA, tile);
    free(tile);
    GLuint raw = texture_2d(f->W, f->H, GL_R32F, GL_RED, NULL);
    const double focal = 1.0 / tan(0.5 * yfov), p00 = focal / ((double)f->W / f->H), p11 = focal;

    char *frag = pass_source(folder, sources, name);
    GLuint prog = compile_pipeline(f->vertex, frag, jstr(sources, name));
    free(frag);
    glUseProgram(prog);
    Json *uniforms = jreq(g, "uniforms");
    for (int k = 0; k < uniforms->n; k++) {
        const char *uname = uniforms->keys[k];
        GLint loc = glGetUniformLocation(prog, uname);
        Json *value = jget(uniforms->items[k], "value"), *times = jget(uniforms->items[k], "times_radius");
        if (value && value->type == J_ARR) {
            float *v = xmalloc(sizeof(float) * (size_t)value->n);
            for (int i = 0; i < value->n; i++) v[i] = (float)value->items[i]->num;
            if (!strncmp(jstr(uniforms->items[k], "type"), "vec3", 4)) glUniform3fv(loc, value->n / 3, v);
            else glUniform1fv(loc, value->n, v);
            free(v);
        } else if (value) glUniform1f(loc, (float)value->num);
        else if (times) glUniform1f(loc, (float)(times->num * radius));
        else if (!strcmp(uname, "u_proj")) glUniform2f(loc, (float)p00, (float)p11);
        else if (!strcmp(uname, "u_radius")) glUniform1f(loc, (float)radius);
        else if (!strcmp(uname, "u_pixels_per_unit")) glUniform1f(loc, (float)(0.5 * f->H * p11));
        else die("manifest: %s uniform %s has a formula this host does not know", name, uname);
    }
    const char *bound[] = {"u_position", "u_normal", "u_noise", "u_raw"};
    GLuint by_name[] = {f->position, f->normal, noise_tex, raw};
    Json *blur = jget(g, "blur");
    const Json *stages[2] = {jreq(g, "textures"), blur && blur->type == J_OBJ ? jreq(blur, "textures") : NULL};
    GLuint progs[2] = {prog, 0}, targets[2] = {raw, raw};
    if (stages[1]) {
        char blur_key[64];
        snprintf(blur_key, sizeof blur_key, "%s_blur", name);
        targets[1] = texture_2d(f->W, f->H, GL_R32F, GL_RED, NULL);
        frag = pass_source(folder, sources, blur_key);
        progs[1] = compile_pipeline(f->vertex, frag, jstr(sources, blur_key));
        free(frag);
    }
    double *runs = xmalloc(sizeof(double) * (size_t)(g_repeats + 1) * 2), *walls = runs + g_repeats + 1;
    for (int run = 0; run <= g_repeats; run++) {
        if (run > 0) time_begin();
        for (int s = 0; s < 2 && stages[s]; s++) {
            for (int k = 0; k < stages[s]->n; k++) {
                int which = -1;
                for (int b = 0; b < 4; b++) if (!strcmp(stages[s]->keys[k], bound[b])) which = b;
                if (which < 0) die("manifest: %s texture %s is not one this host has", name, stages[s]->keys[k]);
                glActiveTexture(GL_TEXTURE0 + (GLenum)stages[s]->items[k]->num);
                glBindTexture(GL_TEXTURE_2D, by_name[which]);
            }
            glActiveTexture(GL_TEXTURE0);
            draw_fullscreen(progs[s], &targets[s], 1, f->W, f->H);
        }
        if (run > 0) runs[run - 1] = time_end_ms(&walls[run - 1]);
    }
    if (g_repeats > 0) *ms = median(runs, g_repeats), *wall = median(walls, g_repeats);
    free(runs);
    GLuint out = stages[1] ? targets[1] : raw;
    glDeleteProgram(progs[0]);
    if (progs[1]) glDeleteProgram(progs[1]);
    glDeleteTextures(1, &noise_tex);
    if (out != raw) glDeleteTextures(1, &raw);
    return out;
}

/* The full-resolution G-buffer as neuralao.runtime.baselines.gbuffer_textures builds it, for the fragment
 * passes: position (camera-space xyz, mask in w) and normal, RGBA32F 2-D textures in GL order (row 0 = the
 * bottom row), zeros on background; and an empty VAO to draw with. gb: H x W x 5 floats, row 0 on top. */
static Frame gbuffer_frame(const float *gb, int W, int H, double yfov, const char *vertex) {
    const size_t px = (size_t)W * H;
    float *pos = xmalloc(sizeof(float) * 4 * px), *nrm = xmalloc(sizeof(float) * 4 * px);
    const double t = tan(0.5 * yfov);
    for (int r = 0; r < H; r++) {
        const double yc = (1.0 - (r + 0.5) / H * 2.0) * t;
        for (int c = 0; c < W; c++) {
            const float *g = gb + ((size_t)r * W + c) * 5;
            float *p = pos + ((size_t)(H - 1 - r) * W + c) * 4, *n = nrm + ((size_t)(H - 1 - r) * W + c) * 4;
            if (!(g[4] >= 0.5f)) continue;
            const double xc = ((c + 0.5) / W * 2.0 - 1.0) * t * ((double)W / H), z = g[0];
            p[0] = (float)(xc * z), p[1] = (float)(yc * z), p[2] = (float)(-z), p[3] = 1.0f;
            for (int k = 0; k < 3; k++) n[k] = isfinite(g[1 + k]) ? g[1 + k] : 0.0f;
        }
    }
    GLuint vao;
    glGenVertexArrays(1, &vao);
    glBindVertexArray(vao);
    Frame f = {texture_2d(W, H, GL_RGBA32F, GL_RGBA, pos), texture_2d(W, H, GL_RGBA32F, GL_RGBA, nrm), vao,
               vertex, W, H};
    free(pos), free(nrm);
    glDisable(GL_DEPTH_TEST), glDisable(GL_BLEND), glDisable(GL_CULL_FACE), glDisable(GL_SCISSOR_TEST);
    return f;
}

static void release_frame(Frame *f) {
    glDeleteTextures(1, &f->position), glDeleteTextures(1, &f->normal), glDeleteVertexArrays(1, &f->vao);
}

/* The whole frame at the manifest's internal resolution: (GTAO,) downsample, network, upsample (, clamp).
 * gb: W x H x 5 floats, row 0 on top. Returns AO W x H, row 0 on top, 1 on background. */
static float *run_internal(const Json *m, const char *dir, const Json *ir, const float *gb,
                           int W, int H, double radius, double yfov, int *n_passes) {
    char folder[4200];
    snprintf(folder, sizeof folder, "%s/%s", dir, jstr(ir, "folder"));
    Json *sources = jreq(ir, "sources");
    const int hybrid = jget(sources, "gtao") != NULL;
    if (hybrid && !jget(ir, "gtao")) die("manifest: a gtao source without its \"gtao\" entry");
    if (jget(ir, "gtao_raw"))
        die("this model also reads GTAO before its blur, which this host's fragment route does not feed: "
            "give it an export with its frame section");
    const int ih = (int)jnum(ir, "height");
    const int lh = ih, lw = (int)fmax(1.0, rint((double)W * ih / H));  /* round half to even, as Python */
    const size_t px = (size_t)W * H, lpx = (size_t)lw * lh;

    char *vertex = pass_source(folder, sources, "vertex");
    Frame f = gbuffer_frame(gb, W, H, yfov, vertex);

    /* hybrid, first: GTAO at the frame's own resolution */
    GLuint gtao_tex = 0;
    float *gtao = NULL;
    if (hybrid) {
        gtao_tex = run_screen_space(&f, folder, sources, "gtao", jreq(ir, "gtao"), radius, yfov, &g_gtao_ms,
                                    &g_gtao_wall_ms);
        gtao = read_2d(gtao_tex, W, H, GL_RED, 1);
    }

    /* downsample.frag: point-sampled G-buffer at lw x lh */
    GLuint low[2] = {texture_2d(lw, lh, GL_RGBA32F, GL_RGBA, NULL), texture_2d(lw, lh, GL_RGBA32F, GL_RGBA, NULL)};
    char *frag = pass_source(folder, sources, "downsample");
    GLuint prog = compile_pipeline(f.vertex, frag, jstr(sources, "downsample"));
    free(frag);
    glActiveTexture(GL_TEXTURE0), glBindTexture(GL_TEXTURE_2D, f.position);
    glActiveTexture(GL_TEXTURE1), glBindTexture(GL_TEXTURE_2D, f.normal);
    glUseProgram(prog);
    glUniform2i(glGetUniformLocation(prog, "u_low_size"), lw, lh);
    draw_fullscreen(prog, low, 2, lw, lh);
    glDeleteProgram(prog);
    float *lpos = read_2d(low[0], lw, lh, GL_RGBA, 4), *lnrm = read_2d(low[1], lw, lh, GL_RGBA, 4);

    /* the network's input at lw x lh, row 0 on top: depth -z / m, normal, (GTAO at the same texels) */
    const int channels = hybrid ? 5 : 4;
    float *planes = xmalloc(sizeof(float) * (size_t)channels * lpx), *ldepth = xmalloc(sizeof(float) * lpx);
    float *lmask = xmalloc(sizeof(float) * lpx), *lgtao = xmalloc(sizeof(float) * lpx);
    for (int r = 0; r < lh; r++)
        for (int c = 0; c < lw; c++) {
            const size_t top = (size_t)r * lw + c, gl_i = (size_t)(lh - 1 - r) * lw + c;
            lmask[top] = lpos[gl_i * 4 + 3], ldepth[top] = -lpos[gl_i * 4 + 2];
            if (hybrid) {  /* the full-resolution pixel downsample.frag read for this texel, GL order */
                const long qx = (2L * c + 1) * W / (2L * lw), qy = (2L * (lh - 1 - r) + 1) * H / (2L * lh);
                lgtao[top] = gtao[(size_t)qy * W + (size_t)qx];
            }
        }
    const float rho = depth_plane_and_rho(preprocess_version(m), ldepth, lmask, lpx, radius, yfov, planes);
    for (size_t i = 0; i < lpx; i++) {
        const int fg = lmask[i] >= 0.5f;
        const size_t r = i / (size_t)lw, c = i % (size_t)lw, gl_i = ((size_t)lh - 1 - r) * (size_t)lw + c;
        for (int k = 0; k < 3; k++) planes[(size_t)(1 + k) * lpx + i] = fg ? lnrm[gl_i * 4 + (size_t)k] : 0.0f;
        if (hybrid) planes[4 * lpx + i] = fg ? lgtao[i] : 1.0f;
    }
    float *y = run_network(m, dir, lw, lh, planes, channels, rho, n_passes);

    /* upsample.frag: the AO (hybrid: its correction to the point-sampled GTAO) to W x H, GL order */
    float *low_ao = xmalloc(sizeof(float) * lpx);
    for (size_t i = 0; i < lpx; i++) {
        const size_t r = i / (size_t)lw, c = i % (size_t)lw, gl_i = ((size_t)lh - 1 - r) * (size_t)lw + c;
        const float ao = lmask[i] >= 0.5f ? y[i] : 1.0f;
        low_ao[gl_i] = hybrid ? ao - (lmask[i] >= 0.5f ? lgtao[i] : 1.0f) : ao;
    }
    GLuint low_ao_tex = texture_2d(lw, lh, GL_R32F, GL_RED, low_ao), up = texture_2d(W, H, GL_R32F, GL_RED, NULL);
    frag = pass_source(folder, sources, "upsample");
    prog = compile_pipeline(f.vertex, frag, jstr(sources, "upsample"));
    free(frag);
    const GLuint units[5] = {0, 1, 4, 5, 6}, texs[5] = {f.position, f.normal, low_ao_tex, low[0], low[1]};
    for (int k = 0; k < 5; k++) glActiveTexture(GL_TEXTURE0 + units[k]), glBindTexture(GL_TEXTURE_2D, texs[k]);
    glActiveTexture(GL_TEXTURE0);
    draw_fullscreen(prog, &up, 1, W, H);
    glDeleteProgram(prog);
    float *upsampled = read_2d(up, W, H, GL_RED, 1);

    /* the AO, row 0 on top: hybrid clamp(GTAO + correction, 0, 1); background 1 */
    float *ao = xmalloc(sizeof(float) * px);
    for (int r = 0; r < H; r++)
        for (int c = 0; c < W; c++) {
            const size_t top = (size_t)r * W + c, gl_i = (size_t)(H - 1 - r) * W + c;
            float v = upsampled[gl_i];
            if (hybrid) v = fminf(fmaxf(gtao[gl_i] + v, 0.0f), 1.0f);
            ao[top] = gb[top * 5 + 4] >= 0.5f ? v : 1.0f;
        }
    *n_passes += 2 + (hybrid ? 1 + (jget(sources, "gtao_blur") ? 1 : 0) : 0);
    release_frame(&f), free(vertex);
    free(lpos), free(lnrm), free(planes), free(ldepth), free(lmask), free(lgtao);
    free(y), free(low_ao), free(upsampled), free(gtao);
    return ao;
}

/* ------------------------------------------------------------------ the whole frame (manifest "frame") */

/* A manifest's texture format (R16: 16-bit unsigned normalised, a hybrid's GTAO at fp16) -> GL's. */
static GLenum internal_format(const char *name) {
    static const char *names[] = {"RGBA32F", "RGBA16F", "R32F", "R16F", "R16"};
    static const GLenum formats[] = {GL_RGBA32F, GL_RGBA16F, GL_R32F, GL_R16F, GL_R16};
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++) if (!strcmp(name, names[i])) return formats[i];
    die("manifest: texture format %s is not one this host allocates", name);
    return 0;
}

enum { STEP_OTHER, STEP_GTAO, STEP_NETWORK }; /* what the timed runs time apart */

typedef struct {
    GLuint prog;
    int n_inputs, in_binding[8];
    Texture *in[8], *out;
    int out_binding, ubo_binding;           /* ubo_binding: -1 for a network pass */
    int params_binding;                     /* -1: no weights */
    GLintptr params_offset;
    GLsizeiptr params_bytes;
    int flip_location;                      /* -1: no u_flip_y */
    GLuint groups[3];
    int kind;                               /* STEP_* */
    char name[64];                          /* the pass's name, for the per-step profile */
} Step;

typedef struct {
    Texture *tex;
    int n_tex;
    Step *steps;
    int n_steps;
    GLuint ssbo, ubo;
} FrameRun;

static Step make_step(const char *dir, const Json *p, FrameRun *fr) {
    char path[4200];
    Step s = {0};
    snprintf(s.name, sizeof s.name, "%s", jstr(p, "name"));
    snprintf(path, sizeof path, "%s/%s", dir, jstr(p, "shader"));
    char *src = read_file(path, NULL);
    s.prog = compile_compute(src, jstr(p, "shader"));
    free(src);
    Json *inputs = jreq(p, "inputs");
    if (inputs->n > 8) die("pass %s reads %d textures, this host binds up to 8", jstr(p, "name"), inputs->n);
    s.n_inputs = inputs->n;
    for (int k = 0; k < inputs->n; k++) {
        s.in_binding[k] = (int)jnum(inputs->items[k], "binding");
        s.in[k] = find_texture(fr->tex, fr->n_tex, jstr(inputs->items[k], "texture"));
    }
    Json *out = jreq(p, "output"), *ub = jget(p, "uniform_block"), *params = jget(p, "params");
    s.out = find_texture(fr->tex, fr->n_tex, jstr(out, "texture"));
    s.out_binding = (int)jnum(out, "binding");
    s.ubo_binding = ub ? (int)jnum(ub, "binding") : -1;
    s.params_binding = params ? (int)jnum(params, "binding") : -1;
    if (params) s.params_offset = (GLintptr)jnum(params, "offset"), s.params_bytes = (GLsizeiptr)jnum(params, "bytes");
    s.flip_location = -1;
    Json *uniforms = jget(p, "uniforms");
    for (int k = 0; uniforms && k < uniforms->n; k++) {
        if (strcmp(uniforms->keys[k], "u_flip_y"))
            die("pass %s: the frame sets no uniform %s", jstr(p, "name"), uniforms->keys[k]);
        s.flip_location = (int)jnum(uniforms->items[k], "location");
    }
    Json *ls = jreq(p, "local_size"), *block = jget(p, "block");
    const int bx = block ? (int)block->items[0]->num : 1, by = block ? (int)block->items[1]->num : 1;
    const int bl = block ? (int)block->items[2]->num : 1;
    const int lx = (int)ls->items[0]->num, ly = (int)ls->items[1]->num;
    s.groups[0] = (GLuint)((s.out->w + lx * bx - 1) / (lx * bx));
    s.groups[1] = (GLuint)((s.out->h + ly * by - 1) / (ly * by));
    s.groups[2] = jget(p, "stage") ? 1 : (GLuint)(s.out->layers / bl); /* a frame pass writes every layer */
    const char *name = jstr(p, "name");
    s.kind = !jget(p, "stage") ? STEP_NETWORK : !strncmp(name, "f_gtao", 6) ? STEP_GTAO : STEP_OTHER;
    return s;
}

/* Dispatches the frame's steps of one kind (or all of them: kind < 0), in order. */
static void dispatch_step(const FrameRun *fr, const Step *s) {
    glUseProgram(s->prog);
    for (int k = 0; k < s->n_inputs; k++) {
        glActiveTexture(GL_TEXTURE0 + (GLenum)s->in_binding[k]);
        glBindTexture(GL_TEXTURE_2D_ARRAY, s->in[k]->tex);
    }
    glBindImageTexture((GLuint)s->out_binding, s->out->tex, 0, GL_TRUE, 0, GL_WRITE_ONLY, s->out->internal);
    if (s->ubo_binding >= 0) glBindBufferBase(GL_UNIFORM_BUFFER, (GLuint)s->ubo_binding, fr->ubo);
    if (s->params_binding >= 0)
        glBindBufferRange(GL_SHADER_STORAGE_BUFFER, (GLuint)s->params_binding, fr->ssbo, s->params_offset,
                          s->params_bytes);
    if (s->flip_location >= 0) glUniform1i(s->flip_location, 0); /* the frame's u_flip_y */
    glDispatchCompute(s->groups[0], s->groups[1], s->groups[2]);
    glMemoryBarrier(GL_TEXTURE_FETCH_BARRIER_BIT | GL_SHADER_IMAGE_ACCESS_BARRIER_BIT);
}

static void dispatch_steps(const FrameRun *fr, int kind) {
    for (int i = 0; i < fr->n_steps; i++)
        if (kind < 0 || fr->steps[i].kind == kind) dispatch_step(fr, &fr->steps[i]);
    glActiveTexture(GL_TEXTURE0);
}

/* Medians of N timed runs (NEURALAO_HOST_REPEATS) of the steps of one kind (all: kind < 0), or of step
 * ``only`` alone (only >= 0). */
static void time_runs(const FrameRun *fr, int kind, int only, double *ms, double *wall) {
    double *runs = xmalloc(sizeof(double) * (size_t)g_repeats * 2), *walls = runs + g_repeats;
    for (int run = 0; run < g_repeats; run++) {
        time_begin();
        if (only >= 0)
            dispatch_step(fr, &fr->steps[only]);
        else
            dispatch_steps(fr, kind);
        runs[run] = time_end_ms(&walls[run]);
    }
    *ms = median(runs, g_repeats), *wall = median(walls, g_repeats);
    free(runs);
}

/* NEURALAO_HOST_PROFILE set (with NEURALAO_HOST_REPEATS): each step timed alone, N times, after the frame
 * has run once (its inputs hold the frame's values); one line per step on stderr, medians in ms. */
static void profile_steps(const FrameRun *fr) {
    if (!getenv("NEURALAO_HOST_PROFILE") || g_repeats < 1) return;
    for (int i = 0; i < fr->n_steps; i++) {
        const Step *s = &fr->steps[i];
        double ms, wall;
        time_runs(fr, -1, i, &ms, &wall);
        fprintf(stderr, "neuralao_host: step %2d %-22s %8.4f ms (wall %.4f), groups %u x %u x %u\n", i, s->name, ms,
                wall, s->groups[0], s->groups[1], s->groups[2]);
    }
    glActiveTexture(GL_TEXTURE0);
}

/* Medians of N timed dispatches of the steps of one kind (all: kind < 0); left as they are when the frame
 * has none. */
static void time_steps(const FrameRun *fr, int kind, double *ms, double *wall) {
    int any = kind < 0;
    for (int i = 0; i < fr->n_steps; i++) any |= fr->steps[i].kind == kind;
    if (any && g_repeats >= 1) time_runs(fr, kind, -1, ms, wall);
}

/* The whole frame from the manifest's "frame" section (see the header, steps 1-5). gb: H x W x 5 floats,
 * row 0 on top. Returns the AO, H x W, row 0 on top. */
static float *run_frame(const Json *m, const char *dir, const float *gb, int W, int H, double radius, double yfov,
                        int *n_passes) {
    const Json *frame = jreq(m, "frame");
    check_frame_inputs(frame);
    int sym[6];
    frame_symbols(m, W, H, sym);

    /* 1. the textures */
    FrameRun fr = {0};
    const Json *tex_json = jreq(frame, "textures");
    fr.n_tex = tex_json->n;
    fr.tex = xmalloc(sizeof(Texture) * (size_t)(fr.n_tex ? fr.n_tex : 1));
    for (int i = 0; i < fr.n_tex; i++) {
        const Json *t = tex_json->items[i];
        Texture *x = &fr.tex[i];
        x->id = tex_json->keys[i];
        x->w = frame_formula(jstr(t, "width"), sym), x->h = frame_formula(jstr(t, "height"), sym);
        x->layers = (int)jnum(t, "layers");
        x->internal = internal_format(jstr(t, "format"));
        if (x->w < 1 || x->h < 1 || x->layers < 1) die("texture %s is %dx%dx%d", x->id, x->w, x->h, x->layers);
        glGenTextures(1, &x->tex);
        glBindTexture(GL_TEXTURE_2D_ARRAY, x->tex);
        glTexStorage3D(GL_TEXTURE_2D_ARRAY, 1, x->internal, x->w, x->h, x->layers);
        glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
        glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    }

    /* 2. the engine's inputs: depth and normal, zero on background, row 0 on top */
    const size_t px = (size_t)W * H;
    const char *input_ids[2] = {"depth", "normal"};
    for (int k = 0; k < 2; k++) {
        Texture *t = find_texture(fr.tex, fr.n_tex, input_ids[k]);
        if (t->w != W || t->h != H) die("input texture %s is %dx%d, the frame %dx%d", t->id, t->w, t->h, W, H);
        const int lanes = t->internal == GL_R32F || t->internal == GL_R16F || t->internal == GL_R16 ? 1 : 4;
        float *data = input_texels(gb, px, k, lanes);
        glBindTexture(GL_TEXTURE_2D_ARRAY, t->tex);
        glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
        glTexSubImage3D(GL_TEXTURE_2D_ARRAY, 0, 0, 0, 0, W, H, 1, lanes == 1 ? GL_RED : GL_RGBA, GL_FLOAT, data);
        free(data);
    }

    /* 3. the FrameUniforms block, the weights */
    size_t ub_bytes;
    unsigned char *block = frame_uniforms(frame, W, H, radius, yfov, &ub_bytes);
    glGenBuffers(1, &fr.ubo);
    glBindBuffer(GL_UNIFORM_BUFFER, fr.ubo);
    glBufferData(GL_UNIFORM_BUFFER, (GLsizeiptr)ub_bytes, block, GL_STATIC_DRAW);
    free(block);
    size_t w_bytes;
    char *weights = read_weights(m, dir, &w_bytes);
    glGenBuffers(1, &fr.ssbo);
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, fr.ssbo);
    glBufferData(GL_SHADER_STORAGE_BUFFER, (GLsizeiptr)(w_bytes ? w_bytes : 16), weights, GL_STATIC_DRAW);
    free(weights);

    /* 4. the steps that run at this size, compiled once; dispatched, then timed */
    const Texture *net_in = find_texture(fr.tex, fr.n_tex, jstr(jreq(m, "input"), "texture"));
    const int same = net_in->w == W && net_in->h == H;
    const Json *steps = jreq(frame, "steps");
    fr.steps = xmalloc(sizeof(Step) * (size_t)(steps->n ? steps->n : 1));
    for (int k = 0; k < steps->n; k++)
        if (step_runs(steps->items[k], same)) fr.steps[fr.n_steps++] = make_step(dir, step_pass(m, steps->items[k]), &fr);
    dispatch_steps(&fr, -1);

    /* 5. the AO, lane 0 of the output texture */
    Texture *res = find_texture(fr.tex, fr.n_tex, jstr(frame, "output"));
    if (res->w != W || res->h != H) die("output texture %s is %dx%d, the frame %dx%d", res->id, res->w, res->h, W, H);
    float *rgba = xmalloc(sizeof(float) * 4 * px * (size_t)res->layers);
    glBindTexture(GL_TEXTURE_2D_ARRAY, res->tex);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glGetTexImage(GL_TEXTURE_2D_ARRAY, 0, GL_RGBA, GL_FLOAT, rgba);
    float *ao = xmalloc(sizeof(float) * px);
    for (size_t i = 0; i < px; i++) ao[i] = rgba[i * 4];
    free(rgba);

    time_steps(&fr, -1, &g_frame_ms, &g_frame_wall_ms);
    time_steps(&fr, STEP_GTAO, &g_gtao_ms, &g_gtao_wall_ms);
    time_steps(&fr, STEP_NETWORK, &g_network_ms, &g_network_wall_ms);
    profile_steps(&fr);

    *n_passes = fr.n_steps;
    for (int i = 0; i < fr.n_steps; i++) glDeleteProgram(fr.steps[i].prog);
    for (int i = 0; i < fr.n_tex; i++) glDeleteTextures(1, &fr.tex[i].tex);
    glDeleteBuffers(1, &fr.ssbo), glDeleteBuffers(1, &fr.ubo);
    free(fr.steps), free(fr.tex);
    return ao;
}

/* The bench's SSAO (EXPORT_DIR/manifest.json "ssao": its fragment passes and how to run them) on the same
 * G-buffer, timed into g_ssao_ms; its AO (H x W, row 0 on top, 1 on background) written to `out` unless
 * that is NULL. */
static void run_ssao(const Json *ssao, const char *export_dir, const float *gb, int W, int H, double radius,
                     double yfov, const char *out_path) {
    char folder[4200];
    snprintf(folder, sizeof folder, "%s/%s", export_dir, jstr(ssao, "folder"));
    const Json *sources = jreq(ssao, "sources");
    char *vertex = pass_source(folder, sources, "vertex");
    Frame f = gbuffer_frame(gb, W, H, yfov, vertex);
    GLuint out = run_screen_space(&f, folder, sources, "ssao", ssao, radius, yfov, &g_ssao_ms, &g_ssao_wall_ms);
    if (out_path) {
        float *gl_rows = read_2d(out, W, H, GL_RED, 1), *ao = xmalloc(sizeof(float) * (size_t)W * H);
        for (int r = 0; r < H; r++)
            for (int c = 0; c < W; c++) {
                const size_t top = (size_t)r * W + c;
                ao[top] = gb[top * 5 + 4] >= 0.5f ? gl_rows[(size_t)(H - 1 - r) * W + c] : 1.0f;
            }
        write_ao(out_path, ao, W, H);
        free(gl_rows), free(ao);
    }
    glDeleteTextures(1, &out);
    release_frame(&f);
    free(vertex);
}

/* ------------------------------------------------------------------ main */

int main(int argc, char **argv) {
    const HostArgs args = parse_args(argc, argv);
    const int W = args.W, H = args.H;
    const double radius = args.radius, yfov = args.yfov;

    /* the export: glsl/manifest.json under EXPORT_DIR (and EXPORT_DIR/manifest.json, whose
     * "internal_resolution" names the fragment passes around the network of an export without a frame
     * section, and whose "ssao" the bench's SSAO), or EXPORT_DIR/manifest.json */
    char dir[4096], path[4200];
    snprintf(dir, sizeof dir, "%s/glsl", argv[1]);
    snprintf(path, sizeof path, "%s/manifest.json", dir);
    Json *internal = NULL, *ssao = NULL;
    if (file_exists(path)) {
        char top_path[4200];
        snprintf(top_path, sizeof top_path, "%s/manifest.json", argv[1]);
        if (file_exists(top_path)) {
            Json *top_manifest = read_json(top_path);
            internal = jget(top_manifest, "internal_resolution");
            if (internal && internal->type != J_OBJ) internal = NULL;  /* null: the frame's own size */
            ssao = jget(top_manifest, "ssao");
            if (ssao && ssao->type != J_OBJ) ssao = NULL;
        }
    } else {
        snprintf(dir, sizeof dir, "%s", argv[1]);
    }
    snprintf(path, sizeof path, "%s/manifest.json", dir);
    Json *m = read_json(path);
    if (strcmp(jstr(m, "format"), "neuralao-glsl-compute")) die("%s is not a GLSL compute export", path);

    g_repeats = host_repeats();
    float *gb = load_gbuffer(argv[2], W, H);

    egl_context();
    int n_passes = 0;
    float *ao;
    const Json *frame = jget(m, "frame");
    const char *route = frame ? "frame" : internal ? "internal" : "network";
    if (frame) {
        ao = run_frame(m, dir, gb, W, H, radius, yfov, &n_passes);
    } else if (internal) {
        ao = run_internal(m, dir, internal, gb, W, H, radius, yfov, &n_passes);
    } else {
        if ((int)jnum(jreq(m, "input"), "channels") != 4)
            die("a hybrid export runs its GTAO pass at an internal resolution; this one declares none");
        /* steps 1-3 at the frame's own size: input planes, rho */
        const size_t px = (size_t)W * H;
        float *planes = xmalloc(sizeof(float) * 4 * px), *depth = xmalloc(sizeof(float) * px);
        float *mask = xmalloc(sizeof(float) * px);
        for (size_t i = 0; i < px; i++) depth[i] = gb[i * 5], mask[i] = gb[i * 5 + 4];
        const float rho = depth_plane_and_rho(preprocess_version(m), depth, mask, px, radius, yfov, planes);
        for (size_t i = 0; i < px; i++)
            if (mask[i] >= 0.5f)
                for (int k = 1; k < 4; k++) planes[(size_t)k * px + i] = gb[i * 5 + (size_t)k];
        ao = run_network(m, dir, W, H, planes, 4, rho, &n_passes);
        for (size_t i = 0; i < px; i++) if (!(mask[i] >= 0.5f)) ao[i] = 1.0f;
        free(planes), free(depth), free(mask);
    }
    const char *ssao_out = getenv("NEURALAO_HOST_SSAO_OUT");
    if (ssao && (g_repeats > 0 || ssao_out)) run_ssao(ssao, argv[1], gb, W, H, radius, yfov, ssao_out);
    else if (ssao_out) die("NEURALAO_HOST_SSAO_OUT is set, but %s/manifest.json has no \"ssao\" entry", argv[1]);
    if (glGetError() != GL_NO_ERROR) die("OpenGL reported an error");

    write_ao(args.out, ao, W, H);
    fprintf(stderr, "neuralao_host: %dx%d (%s), %d passes -> %s\n", W, H, route, n_passes, argv[7]);
    if (g_repeats > 0)
        printf("{\"renderer\": \"%s\", \"version\": \"%s\", \"width\": %d, \"height\": %d, \"repeats\": %d, "
               "\"path\": \"%s\", \"frame_ms\": %.4f, \"network_ms\": %.4f, \"gtao_ms\": %.4f, \"ssao_ms\": %.4f, "
               "\"frame_wall_ms\": %.4f, \"network_wall_ms\": %.4f, \"gtao_wall_ms\": %.4f, "
               "\"ssao_wall_ms\": %.4f, \"passes\": %d}\n",
               (const char *)glGetString(GL_RENDERER), (const char *)glGetString(GL_VERSION), W, H, g_repeats,
               route, g_frame_ms, g_network_ms, g_gtao_ms, g_ssao_ms, g_frame_wall_ms, g_network_wall_ms,
               g_gtao_wall_ms, g_ssao_wall_ms, n_passes);
    return 0;
}
