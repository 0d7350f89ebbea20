/*
 * neuralao_host: the reference engine integration of a shipped screen-space AO export, in C.
 *
 *   neuralao_host EXPORT_DIR GBUFFER.f32 WIDTH HEIGHT RADIUS YFOV OUT.f32
 *
 * EXPORT_DIR   a shipped export (runtime/models/<name>, holding glsl/manifest.json) or its glsl/ folder
 * GBUFFER.f32  raw float32 little-endian, HEIGHT x WIDTH pixels, row 0 = the top row, 5 floats a pixel:
 *              linear camera-space depth z (> 0 in front of the camera, 0 on background),
 *              camera-space unit normal nx, ny, nz (OpenGL axes, facing the viewer), mask (>= 0.5 foreground)
 * RADIUS       AO radius in scene units; YFOV the vertical field of view in radians
 * OUT.f32      raw float32, HEIGHT x WIDTH, row 0 = the top row: AO in [0, 1], 1 on background
 *
 * What an engine does around the generated passes (docs/engine-integration.md, steps 1-4), by the input
 * contract the export's ONNX metadata names (source_model_metadata.preprocess_version):
 *   version 3 (frame-local):
 *   1. nothing: no statistic of the frame is needed;
 *   2. the network input texture t0: (log z, n) on foreground, 0 on background, RGBA32F layers;
 *   3. the radius uniform rho = log(R / tan(yfov / 2)) of the pass the manifest's "uniforms" names;
 *   version 2 (whole frame): 1. mean foreground depth m (here on the CPU, in double; an engine runs a
 *   reduction pass); 2. t0 = (z / m, n); 3. rho = R / (m * tan(yfov / 2));
 *   4. every texture of the manifest allocated at its size formula (W, Wp = ceil(W / p) * p, ...);
 *      the passes in order (the generated pad pass pads, the crop pass crops), one dispatch each,
 *      a memory barrier between them; the output texture read back, background set to 1.
 * An export whose manifest.json declares "internal_resolution" runs around them the fragment passes it
 * names (docs/engine-integration.md, "Internal resolution"): for a hybrid first its GTAO pass (gtao.frag,
 * its blur) at W x H, then the point-sampling pass to the internal size, the network there (steps 1-4 on
 * the point-sampled G-buffer, GTAO point-sampled as the fifth channel), the upsampling pass back to
 * W x H, and for a hybrid AO = clamp(GTAO + upsampled correction, 0, 1).
 *
 * Timing (bench/gpu.sh): with NEURALAO_HOST_REPEATS=N set, the network's passes (and a hybrid's GTAO
 * passes) run N more times after the frame, each run between GL_TIME_ELAPSED queries, and one JSON line
 * goes to stdout: {"renderer", "width", "height", "network_ms", "gtao_ms", "passes"} (medians, GPU time).
 * GBUFFER.f32 may be the word "synthetic": a seeded wavy surface filling the frame (all foreground).
 *
 * Context: EGL's surfaceless platform (Mesa, or NVIDIA's EGL through glvnd), OpenGL 4.3 core.
 * The manifest is read by the small JSON reader below (objects, arrays, strings, numbers, literals).
 */
#define _POSIX_C_SOURCE 200809L /* clock_gettime */
#define GL_GLEXT_PROTOTYPES 1
#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GL/glcorearb.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static void die(const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    fputs("neuralao_host: ", stderr);
    vfprintf(stderr, fmt, ap);
    fputc('\n', stderr);
    va_end(ap);
    exit(1);
}

static void *xmalloc(size_t n) {
    void *p = calloc(1, n ? n : 1);
    if (!p) die("out of memory");
    return p;
}

static char *read_file(const char *path, size_t *size) {
    FILE *f = fopen(path, "rb");
    if (!f) die("cannot open %s", path);
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    char *buf = xmalloc((size_t)n + 1);
    if (n > 0 && fread(buf, 1, (size_t)n, f) != (size_t)n) die("cannot read %s", path);
    fclose(f);
    if (size) *size = (size_t)n;
    return buf;
}

/* ------------------------------------------------------------------ GPU timing */

static int g_repeats = 0;                        /* NEURALAO_HOST_REPEATS: timed runs after the frame */
static double g_network_ms = -1, g_gtao_ms = -1; /* medians of the timed runs (GL_TIME_ELAPSED); -1: not timed */
/* the same runs on the wall clock between glFinish calls: Mesa's llvmpipe reports 0 GPU time for compute */
static double g_network_wall_ms = -1, g_gtao_wall_ms = -1;
static double g_wall_start;

static int cmp_double(const void *a, const void *b) {
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static GLuint g_query;

static double wall_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

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

static double median(double *v, int n) {
    qsort(v, (size_t)n, sizeof(double), cmp_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/* ------------------------------------------------------------------ JSON reader */

enum { J_NULL, J_BOOL, J_NUM, J_STR, J_ARR, J_OBJ };

typedef struct Json {
    int type;
    double num;
    char *str;            /* J_STR value */
    int n;                /* J_ARR / J_OBJ: number of items */
    char **keys;          /* J_OBJ */
    struct Json **items;  /* J_ARR / J_OBJ */
} Json;

typedef struct { const char *s; } Reader;

static void skip_ws(Reader *r) {
    while (*r->s == ' ' || *r->s == '\n' || *r->s == '\r' || *r->s == '\t') r->s++;
}

static Json *parse_value(Reader *r);

static char *parse_string(Reader *r) {
    if (*r->s != '"') die("manifest: expected a string");
    r->s++;
    size_t cap = 16, len = 0;
    char *out = xmalloc(cap);
    while (*r->s != '"') {
        char c = *r->s++;
        if (!c) die("manifest: unterminated string");
        if (c == '\\') {
            char e = *r->s++;
            switch (e) {
                case 'n': c = '\n'; break;
                case 't': c = '\t'; break;
                case 'r': c = '\r'; break;
                case 'b': c = '\b'; break;
                case 'f': c = '\f'; break;
                case 'u': {  /* keep ASCII, replace the rest by '?': names only, never parsed further */
                    unsigned v = 0;
                    for (int i = 0; i < 4; i++) {
                        char h = *r->s++;
                        v = v * 16 + (unsigned)(h <= '9' ? h - '0' : (h | 32) - 'a' + 10);
                    }
                    c = v < 128 ? (char)v : '?';
                    break;
                }
                default: c = e;  /* \" \\ \/ */
            }
        }
        if (len + 2 > cap) out = realloc(out, cap *= 2);
        out[len++] = c;
    }
    r->s++;
    out[len] = 0;
    return out;
}

static void push(Json *j, char *key, Json *item) {
    j->items = realloc(j->items, sizeof(Json *) * (size_t)(j->n + 1));
    if (j->type == J_OBJ) j->keys = realloc(j->keys, sizeof(char *) * (size_t)(j->n + 1)), j->keys[j->n] = key;
    j->items[j->n++] = item;
}

static Json *parse_value(Reader *r) {
    skip_ws(r);
    Json *j = xmalloc(sizeof(Json));
    char c = *r->s;
    if (c == '{' || c == '[') {
        j->type = c == '{' ? J_OBJ : J_ARR;
        char close = c == '{' ? '}' : ']';
        r->s++;
        skip_ws(r);
        if (*r->s == close) { r->s++; return j; }
        for (;;) {
            char *key = NULL;
            if (j->type == J_OBJ) {
                skip_ws(r);
                key = parse_string(r);
                skip_ws(r);
                if (*r->s++ != ':') die("manifest: expected ':'");
            }
            push(j, key, parse_value(r));
            skip_ws(r);
            if (*r->s == ',') { r->s++; continue; }
            if (*r->s++ != close) die("manifest: expected ',' or '%c'", close);
            return j;
        }
    }
    if (c == '"') { j->type = J_STR; j->str = parse_string(r); return j; }
    if (!strncmp(r->s, "true", 4)) { j->type = J_BOOL; j->num = 1; r->s += 4; return j; }
    if (!strncmp(r->s, "false", 5)) { j->type = J_BOOL; r->s += 5; return j; }
    if (!strncmp(r->s, "null", 4)) { j->type = J_NULL; r->s += 4; return j; }
    char *end;
    j->type = J_NUM;
    j->num = strtod(r->s, &end);
    if (end == r->s) die("manifest: unexpected character '%c'", c);
    r->s = end;
    return j;
}

static Json *jget(const Json *j, const char *key) {  /* NULL when absent */
    if (!j || j->type != J_OBJ) return NULL;
    for (int i = 0; i < j->n; i++) if (!strcmp(j->keys[i], key)) return j->items[i];
    return NULL;
}

static Json *jreq(const Json *j, const char *key) {
    Json *v = jget(j, key);
    if (!v) die("manifest: missing \"%s\"", key);
    return v;
}

static double jnum(const Json *j, const char *key) {
    Json *v = jreq(j, key);
    if (v->type != J_NUM) die("manifest: \"%s\" is not a number", key);
    return v->num;
}

static const char *jstr(const Json *j, const char *key) {
    Json *v = jreq(j, key);
    if (v->type != J_STR) die("manifest: \"%s\" is not a string", key);
    return v->str;
}

/* ------------------------------------------------------------------ GL context */

static void egl_context(void) {
    PFNEGLGETPLATFORMDISPLAYEXTPROC get_display =
        (PFNEGLGETPLATFORMDISPLAYEXTPROC)eglGetProcAddress("eglGetPlatformDisplayEXT");
    if (!get_display) die("EGL lacks eglGetPlatformDisplayEXT");
    EGLDisplay dpy = get_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, NULL);
    EGLint major, minor;
    if (dpy == EGL_NO_DISPLAY || !eglInitialize(dpy, &major, &minor)) die("no surfaceless EGL display (Mesa)");
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
    Json *wj = jreq(m, "weights");
    snprintf(path, sizeof path, "%s/%s", dir, jstr(wj, "file"));
    size_t w_bytes;
    char *weights = read_file(path, &w_bytes);
    if ((double)w_bytes != jnum(wj, "bytes")) die("%s holds %zu bytes, the manifest says %.0f", path, w_bytes, jnum(wj, "bytes"));
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

/* The export's GTAO pass (manifest "gtao") at W x H: gtao.frag, then gtao_blur.frag when it has one.
 * Returns the R32F GTAO texture. Uniforms with a "value" are set as given; the three with a formula
 * are the ones neuralao.runtime.baselines computes from the frame (u_proj, u_radius, u_pixels_per_unit). */
static GLuint run_gtao(const Frame *f, const char *folder, const Json *sources, const Json *g, double radius,
                       double yfov) {
    Json *noise = jreq(g, "noise"), *texels = jreq(noise, "texels");
    const int nw = (int)jnum(noise, "width"), nh = (int)jnum(noise, "height");
    if (texels->n != nw * nh * 4) die("manifest: the GTAO noise tile has %d values, not %d", texels->n, nw * nh * 4);
    float *tile = xmalloc(sizeof(float) * (size_t)texels->n);
    for (int i = 0; i < texels->n; i++) tile[i] = (float)texels->items[i]->num;
    GLuint noise_tex = texture_2d(nw, nh, GL_RGBA32F, GL_RGBA, tile);
    free(tile);
    GLuint raw = texture_2d(f->W, f->H, GL_R32F, GL_RED, NULL);
    const double focal = 1.0 / tan(0.5 * yfov), p00 = focal / ((double)f->W / f->H), p11 = focal;

    char *frag = pass_source(folder, sources, "gtao");
    GLuint prog = compile_pipeline(f->vertex, frag, jstr(sources, "gtao"));
    free(frag);
    glUseProgram(prog);
    Json *uniforms = jreq(g, "uniforms");
    for (int k = 0; k < uniforms->n; k++) {
        const char *name = uniforms->keys[k];
        GLint loc = glGetUniformLocation(prog, name);
        Json *value = jget(uniforms->items[k], "value");
        if (value) glUniform1f(loc, (float)value->num);
        else if (!strcmp(name, "u_proj")) glUniform2f(loc, (float)p00, (float)p11);
        else if (!strcmp(name, "u_radius")) glUniform1f(loc, (float)radius);
        else if (!strcmp(name, "u_pixels_per_unit")) glUniform1f(loc, (float)(0.5 * f->H * p11));
        else die("manifest: GTAO uniform %s has a formula this host does not know", name);
    }
    const char *bound[] = {"u_position", "u_normal", "u_noise", "u_raw"};
    GLuint by_name[] = {f->position, f->normal, noise_tex, raw};
    Json *blur = jget(g, "blur");
    const Json *stages[2] = {jreq(g, "textures"), blur && blur->type == J_OBJ ? jreq(blur, "textures") : NULL};
    GLuint progs[2] = {prog, 0}, targets[2] = {raw, raw};
    if (stages[1]) {
        targets[1] = texture_2d(f->W, f->H, GL_R32F, GL_RED, NULL);
        frag = pass_source(folder, sources, "gtao_blur");
        progs[1] = compile_pipeline(f->vertex, frag, jstr(sources, "gtao_blur"));
        free(frag);
    }
    double *runs = xmalloc(sizeof(double) * (size_t)(g_repeats + 1) * 2), *walls = runs + g_repeats + 1;
    for (int run = 0; run <= g_repeats; run++) {
        if (run > 0) time_begin();
        for (int s = 0; s < 2 && stages[s]; s++) {
            for (int k = 0; k < stages[s]->n; k++) {
                int which = -1;
                for (int b = 0; b < 4; b++) if (!strcmp(stages[s]->keys[k], bound[b])) which = b;
                if (which < 0) die("manifest: GTAO texture %s is not one this host has", stages[s]->keys[k]);
                glActiveTexture(GL_TEXTURE0 + (GLenum)stages[s]->items[k]->num);
                glBindTexture(GL_TEXTURE_2D, by_name[which]);
            }
            glActiveTexture(GL_TEXTURE0);
            draw_fullscreen(progs[s], &targets[s], 1, f->W, f->H);
        }
        if (run > 0) runs[run - 1] = time_end_ms(&walls[run - 1]);
    }
    if (g_repeats > 0) g_gtao_ms = median(runs, g_repeats), g_gtao_wall_ms = median(walls, g_repeats);
    free(runs);
    GLuint out = stages[1] ? targets[1] : raw;
    glDeleteProgram(progs[0]);
    if (progs[1]) glDeleteProgram(progs[1]);
    glDeleteTextures(1, &noise_tex);
    if (out != raw) glDeleteTextures(1, &raw);
    return out;
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
    const int ih = (int)jnum(ir, "height");
    const int lh = ih, lw = (int)fmax(1.0, rint((double)W * ih / H));  /* round half to even, as Python */
    const size_t px = (size_t)W * H, lpx = (size_t)lw * lh;

    /* the full-resolution G-buffer as neuralao.runtime.baselines.gbuffer_textures builds it, GL order */
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
               pass_source(folder, sources, "vertex"), W, H};
    glDisable(GL_DEPTH_TEST), glDisable(GL_BLEND), glDisable(GL_CULL_FACE), glDisable(GL_SCISSOR_TEST);

    /* hybrid, first: GTAO at the frame's own resolution */
    GLuint gtao_tex = 0;
    float *gtao = NULL;
    if (hybrid) {
        gtao_tex = run_gtao(&f, folder, sources, jreq(ir, "gtao"), radius, yfov);
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
    free(pos), free(nrm), free(lpos), free(lnrm), free(planes), free(ldepth), free(lmask), free(lgtao);
    free(y), free(low_ao), free(upsampled), free(gtao);
    return ao;
}

/* ------------------------------------------------------------------ main */

int main(int argc, char **argv) {
    if (argc != 8) {
        fprintf(stderr, "usage: neuralao_host EXPORT_DIR GBUFFER.f32 WIDTH HEIGHT RADIUS YFOV_DEG OUT.f32\n"
                        "  GBUFFER.f32: HEIGHT x WIDTH x (depth, nx, ny, nz, mask) float32, row 0 on top\n");
        return 2;
    }
    const int W = atoi(argv[3]), H = atoi(argv[4]);
    const double radius = atof(argv[5]), yfov_deg = atof(argv[6]);
    const double yfov = yfov_deg * 3.14159265358979323846 / 180.0; /* degrees, as on every neuralao command */
    if (W < 1 || H < 1) die("WIDTH and HEIGHT must be positive");
    if (!(radius > 0) || !(yfov_deg > 0 && yfov_deg < 180)) die("RADIUS must be > 0 and YFOV_DEG in (0, 180) degrees");

    /* the export: glsl/manifest.json under EXPORT_DIR (and EXPORT_DIR/manifest.json, whose
     * "internal_resolution" names the fragment passes around the network), or EXPORT_DIR/manifest.json */
    char dir[4096], path[4200];
    snprintf(dir, sizeof dir, "%s/glsl", argv[1]);
    snprintf(path, sizeof path, "%s/manifest.json", dir);
    FILE *probe = fopen(path, "rb");
    Json *internal = NULL;
    if (probe) {
        fclose(probe);
        char top_path[4200];
        snprintf(top_path, sizeof top_path, "%s/manifest.json", argv[1]);
        FILE *top = fopen(top_path, "rb");
        if (top) {
            fclose(top);
            Reader tr = {read_file(top_path, NULL)};
            internal = jget(parse_value(&tr), "internal_resolution");
            if (internal && internal->type != J_OBJ) internal = NULL;  /* null: the frame's own size */
        }
    } else {
        snprintf(dir, sizeof dir, "%s", argv[1]);
    }
    snprintf(path, sizeof path, "%s/manifest.json", dir);
    char *text = read_file(path, NULL);
    Reader rd = {text};
    Json *m = parse_value(&rd);
    if (strcmp(jstr(m, "format"), "neuralao-glsl-compute")) die("%s is not a GLSL compute export", path);

    const char *repeats = getenv("NEURALAO_HOST_REPEATS");
    g_repeats = repeats ? atoi(repeats) : 0;
    if (g_repeats < 0 || g_repeats > 10000) die("NEURALAO_HOST_REPEATS must be 0..10000");
    size_t gb_bytes;
    float *gb;
    if (!strcmp(argv[2], "synthetic")) {  /* a wavy surface facing the camera, every pixel foreground */
        gb_bytes = (size_t)W * H * 5 * sizeof(float);
        gb = xmalloc(gb_bytes);
        for (int r = 0; r < H; r++)
            for (int c = 0; c < W; c++) {
                float *g = gb + ((size_t)r * W + c) * 5;
                const double u = 12.0 * c / W, v = 8.0 * r / H, dzu = 0.3 * cos(u) * sin(v), dzv = 0.3 * sin(u) * cos(v);
                const double n = sqrt(dzu * dzu + dzv * dzv + 1.0);
                g[0] = (float)(3.0 + 0.3 * sin(u) * sin(v)), g[1] = (float)(dzu / n), g[2] = (float)(-dzv / n);
                g[3] = (float)(1.0 / n), g[4] = 1.0f;
            }
    } else {
        gb = (float *)read_file(argv[2], &gb_bytes);
    }
    if (gb_bytes != (size_t)W * H * 5 * sizeof(float))
        die("%s holds %zu bytes, a %dx%d G-buffer of 5 floats a pixel needs %zu", argv[2], gb_bytes, W, H,
            (size_t)W * H * 5 * sizeof(float));

    egl_context();
    int n_passes = 0;
    float *ao;
    if (internal) {
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
    if (glGetError() != GL_NO_ERROR) die("OpenGL reported an error");

    char tmp[4200];
    snprintf(tmp, sizeof tmp, "%s.tmp", argv[7]);
    FILE *f = fopen(tmp, "wb");
    if (!f || fwrite(ao, sizeof(float), (size_t)W * H, f) != (size_t)W * H || fclose(f)) die("cannot write %s", tmp);
    if (rename(tmp, argv[7])) die("cannot rename %s to %s", tmp, argv[7]);
    fprintf(stderr, "neuralao_host: %dx%d%s, %d passes -> %s\n", W, H, internal ? " (internal resolution)" : "",
            n_passes, argv[7]);
    if (g_repeats > 0)
        printf("{\"renderer\": \"%s\", \"version\": \"%s\", \"width\": %d, \"height\": %d, \"repeats\": %d, "
               "\"network_ms\": %.4f, \"gtao_ms\": %.4f, \"network_wall_ms\": %.4f, \"gtao_wall_ms\": %.4f, "
               "\"passes\": %d}\n",
               (const char *)glGetString(GL_RENDERER), (const char *)glGetString(GL_VERSION), W, H, g_repeats,
               g_network_ms, g_gtao_ms, g_network_wall_ms, g_gtao_wall_ms, n_passes);
    return 0;
}
