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
 * What an engine does around the generated passes (docs/engine-integration.md, steps 1-4):
 *   1. mean foreground depth m (here on the CPU, in double; an engine runs a reduction pass);
 *   2. the network input texture t0: (z / m, n) on foreground, 0 on background, RGBA32F layers;
 *   3. the radius uniform rho = R / (m * tan(yfov / 2)) of the pass the manifest's "uniforms" names;
 *   4. every texture of the manifest allocated at its size formula (W, Wp = ceil(W / p) * p, ...);
 *      the passes in order (the generated pad pass pads, the crop pass crops), one dispatch each,
 *      a memory barrier between them; the output texture read back, background set to 1.
 * The network runs at the frame's own size (an export's internal-resolution fragment passes are not
 * run here).
 *
 * Context: EGL on Mesa's surfaceless platform (no window, no display server), OpenGL 4.3 core.
 * The manifest is read by the small JSON reader below (objects, arrays, strings, numbers, literals).
 */
#define GL_GLEXT_PROTOTYPES 1
#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GL/glcorearb.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

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

    /* the export: glsl/manifest.json under EXPORT_DIR, or EXPORT_DIR/manifest.json itself */
    char dir[4096], path[4200];
    snprintf(dir, sizeof dir, "%s/glsl", argv[1]);
    snprintf(path, sizeof path, "%s/manifest.json", dir);
    FILE *probe = fopen(path, "rb");
    if (probe) fclose(probe); else snprintf(dir, sizeof dir, "%s", argv[1]);
    snprintf(path, sizeof path, "%s/manifest.json", dir);
    char *text = read_file(path, NULL);
    Reader rd = {text};
    Json *m = parse_value(&rd);
    if (strcmp(jstr(m, "format"), "neuralao-glsl-compute")) die("%s is not a GLSL compute export", path);
    const int p = (int)jnum(jreq(m, "pad"), "multiple");
    if (W < p || H < p) die("a %dx%d frame is smaller than the pad multiple %d", W, H, p);
    const int Wp = (W + p - 1) / p * p, Hp = (H + p - 1) / p * p;

    /* the G-buffer and step 1: mean foreground depth */
    size_t gb_bytes;
    float *gb = (float *)read_file(argv[2], &gb_bytes);
    if (gb_bytes != (size_t)W * H * 5 * sizeof(float))
        die("%s holds %zu bytes, a %dx%d G-buffer of 5 floats a pixel needs %zu", argv[2], gb_bytes, W, H,
            (size_t)W * H * 5 * sizeof(float));
    double sum = 0.0;
    long count = 0;
    for (long i = 0; i < (long)W * H; i++)
        if (gb[i * 5 + 4] >= 0.5f) sum += gb[i * 5], count++;
    const double mean_depth = count ? sum / (double)count : 1.0;
    /* step 3: the radius in units of half the screen height at the mean depth */
    const float rho = (float)(radius / (mean_depth * tan(0.5 * yfov)));

    egl_context();

    /* step 4: every texture at its size formula */
    Json *tex_json = jreq(m, "textures");
    int n_tex = tex_json->n;
    Texture *tex = xmalloc(sizeof(Texture) * (size_t)n_tex);
    for (int i = 0; i < n_tex; i++) {
        Json *t = tex_json->items[i];
        tex[i].id = tex_json->keys[i];
        tex[i].w = dim_size(jreq(t, "width"), W, H, Wp, Hp);
        tex[i].h = dim_size(jreq(t, "height"), W, H, Wp, Hp);
        tex[i].layers = (int)jnum(t, "layers");
        tex[i].internal = !strcmp(jstr(t, "format"), "RGBA16F") ? GL_RGBA16F : GL_RGBA32F;
        glGenTextures(1, &tex[i].tex);
        glBindTexture(GL_TEXTURE_2D_ARRAY, tex[i].tex);
        glTexStorage3D(GL_TEXTURE_2D_ARRAY, 1, tex[i].internal, tex[i].w, tex[i].h, tex[i].layers);
        glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
        glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    }

    /* step 2: the network input, (z / m, n) on foreground and 0 on background, 4 channels a layer */
    Texture *in = find_texture(tex, n_tex, jstr(jreq(m, "input"), "texture"));
    if (in->w != W || in->h != H) die("input texture %s is %dx%d, expected the frame's %dx%d", in->id, in->w, in->h, W, H);
    if ((int)jnum(jreq(m, "input"), "channels") != 4) die("this host feeds 4 channels (a hybrid needs GTAO first)");
    float *x = xmalloc(sizeof(float) * 4 * (size_t)W * H * (size_t)in->layers);
    const float m32 = (float)mean_depth;
    for (long i = 0; i < (long)W * H; i++) {
        const float *g = gb + i * 5;
        if (g[4] >= 0.5f) x[i * 4] = g[0] / m32, x[i * 4 + 1] = g[1], x[i * 4 + 2] = g[2], x[i * 4 + 3] = g[3];
    }
    glBindTexture(GL_TEXTURE_2D_ARRAY, in->tex);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTexSubImage3D(GL_TEXTURE_2D_ARRAY, 0, 0, 0, 0, W, H, in->layers, GL_RGBA, GL_FLOAT, x);

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

    /* the passes, in order */
    Json *passes = jreq(m, "passes");
    for (int i = 0; i < passes->n; i++) {
        Json *ps = passes->items[i];
        const char *shader = jstr(ps, "shader"), *kind = jstr(ps, "kind");
        snprintf(path, sizeof path, "%s/%s", dir, shader);
        char *src = read_file(path, NULL);
        GLuint prog = compile_compute(src, shader);
        free(src);
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
        glDeleteProgram(prog);
    }

    /* the output: lane 0 of layer 0 of the first output texture, background 1 */
    Texture *res = find_texture(tex, n_tex, jstr(jreq(m, "outputs")->items[0], "texture"));
    float *rgba = xmalloc(sizeof(float) * 4 * (size_t)res->w * res->h * (size_t)res->layers);
    glBindTexture(GL_TEXTURE_2D_ARRAY, res->tex);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glGetTexImage(GL_TEXTURE_2D_ARRAY, 0, GL_RGBA, GL_FLOAT, rgba);
    if (glGetError() != GL_NO_ERROR) die("OpenGL reported an error");
    float *ao = xmalloc(sizeof(float) * (size_t)W * H);
    for (long i = 0; i < (long)W * H; i++) ao[i] = gb[i * 5 + 4] >= 0.5f ? rgba[i * 4] : 1.0f;
    char tmp[4200];
    snprintf(tmp, sizeof tmp, "%s.tmp", argv[7]);
    FILE *f = fopen(tmp, "wb");
    if (!f || fwrite(ao, sizeof(float), (size_t)W * H, f) != (size_t)W * H || fclose(f)) die("cannot write %s", tmp);
    if (rename(tmp, argv[7])) die("cannot rename %s to %s", tmp, argv[7]);
    fprintf(stderr, "neuralao_host: %dx%d, mean depth %.6g, rho %.6g, %d passes -> %s\n", W, H, mean_depth, rho,
            passes->n, argv[7]);
    return 0;
}
