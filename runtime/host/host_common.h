/*
 * host_common.h: what the reference hosts share (neuralao_host.c, OpenGL; neuralao_vk.c, Vulkan), one header
 * of static functions: the command line, the G-buffer file and the synthetic frame, the AO file, errors and
 * allocation, medians, the small JSON reader of the manifests (objects, arrays, strings, numbers, literals),
 * the frame section's size formulas, step conditions and FrameUniforms block.
 *
 * Define HOST_NAME (the program's name, the prefix of its error lines) before including it.
 */
#ifndef NEURALAO_HOST_COMMON_H
#define NEURALAO_HOST_COMMON_H

#ifndef HOST_NAME
#error "define HOST_NAME (the program's name) before including host_common.h"
#endif

#include <ctype.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static void die(const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    fputs(HOST_NAME ": ", stderr);
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

/* Whether path can be opened for reading. */
static int file_exists(const char *path) {
    FILE *f = fopen(path, "rb");
    if (f) fclose(f);
    return f != NULL;
}

/* ------------------------------------------------------------------ timing */

static int cmp_double(const void *a, const void *b) {
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static double wall_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static double median(double *v, int n) {
    qsort(v, (size_t)n, sizeof(double), cmp_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/* NEURALAO_HOST_REPEATS: the timed runs after the frame (0 when unset). */
static int host_repeats(void) {
    const char *repeats = getenv("NEURALAO_HOST_REPEATS");
    const int n = repeats ? atoi(repeats) : 0;
    if (n < 0 || n > 10000) die("NEURALAO_HOST_REPEATS must be 0..10000");
    return n;
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

/* The JSON document in the file at path (dies when it cannot be read or parsed). */
static Json *read_json(const char *path) {
    Reader rd = {read_file(path, NULL)};
    return parse_value(&rd);
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

/* ------------------------------------------------------------------ the command line and the files */

typedef struct {
    const char *export_dir, *gbuffer, *out;
    int W, H;
    double radius, yfov; /* yfov in radians */
} HostArgs;

/* EXPORT_DIR GBUFFER.f32 WIDTH HEIGHT RADIUS YFOV_DEG OUT.f32; exits 2 with the usage on a wrong count. */
static HostArgs parse_args(int argc, char **argv) {
    if (argc != 8) {
        fprintf(stderr, "usage: " HOST_NAME " EXPORT_DIR GBUFFER.f32 WIDTH HEIGHT RADIUS YFOV_DEG OUT.f32\n"
                        "  GBUFFER.f32: HEIGHT x WIDTH x (depth, nx, ny, nz, mask) float32, row 0 on top\n");
        exit(2);
    }
    HostArgs a = {argv[1], argv[2], argv[7], atoi(argv[3]), atoi(argv[4]), atof(argv[5]), 0.0};
    const double yfov_deg = atof(argv[6]);
    a.yfov = yfov_deg * 3.14159265358979323846 / 180.0; /* degrees, as on every neuralao command */
    if (a.W < 1 || a.H < 1) die("WIDTH and HEIGHT must be positive");
    if (!(a.radius > 0) || !(yfov_deg > 0 && yfov_deg < 180)) die("RADIUS must be > 0 and YFOV_DEG in (0, 180) degrees");
    return a;
}

/* The G-buffer: H x W x 5 floats (depth, nx, ny, nz, mask), row 0 on top, read from `path`, or for the word
 * "synthetic" a seeded wavy surface facing the camera, every pixel foreground. */
static float *load_gbuffer(const char *path, int W, int H) {
    size_t gb_bytes;
    float *gb;
    if (!strcmp(path, "synthetic")) {
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
        gb = (float *)read_file(path, &gb_bytes);
    }
    if (gb_bytes != (size_t)W * H * 5 * sizeof(float))
        die("%s holds %zu bytes, a %dx%d G-buffer of 5 floats a pixel needs %zu", path, gb_bytes, W, H,
            (size_t)W * H * 5 * sizeof(float));
    return gb;
}

/* Writes W x H floats to path through a temporary file: a failed run leaves no partial output. */
static void write_ao(const char *path, const float *ao, int W, int H) {
    char tmp[4200];
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    FILE *f = fopen(tmp, "wb");
    if (!f || fwrite(ao, sizeof(float), (size_t)W * H, f) != (size_t)W * H || fclose(f)) die("cannot write %s", tmp);
    if (rename(tmp, path)) die("cannot rename %s to %s", tmp, path);
}

/* The export's weights file (manifest "weights", in dir), checked against the size the manifest states;
 * *bytes: its size. */
static char *read_weights(const Json *m, const char *dir, size_t *bytes) {
    char path[4200];
    const Json *wj = jreq(m, "weights");
    snprintf(path, sizeof path, "%s/%s", dir, jstr(wj, "file"));
    char *weights = read_file(path, bytes);
    if ((double)*bytes != jnum(wj, "bytes"))
        die("%s holds %zu bytes, the manifest says %.0f", path, *bytes, jnum(wj, "bytes"));
    return weights;
}

/* ------------------------------------------------------------------ the whole frame (manifest "frame") */

/* A size formula of the frame section: a number ("1"), or a symbol (W, H: the frame; w, h: the network's
 * input; wp, hp: those padded) with an optional "*num/den", then an optional "+n" / "-n" ("wp*1/8"). */
static int frame_formula(const char *formula, const int sym[6]) {
    static const char *names[6] = {"W", "H", "w", "h", "wp", "hp"};
    const char *s = formula;
    char name[16] = {0};
    size_t n = 0;
    while ((isalnum((unsigned char)*s) || *s == '_') && n + 1 < sizeof name) name[n++] = *s++;
    long value = 0;
    char *end;
    if (n && strspn(name, "0123456789") == n) {
        value = atol(name);
    } else if (n) {
        int k = 0;
        while (k < 6 && strcmp(name, names[k])) k++;
        if (k == 6) die("manifest: size formula %s names no size this host knows", formula);
        value = sym[k];
        if (*s == '*') {
            const long num = strtol(s + 1, &end, 10);
            if (*end != '/') die("manifest: size formula %s is not symbol[*num/den][+-offset]", formula);
            const long den = strtol(end + 1, &end, 10);
            if (den <= 0) die("manifest: size formula %s divides by %ld", formula, den);
            value = value * num / den, s = end;
        }
    }
    if (*s == '+' || *s == '-') value += strtol(s, &end, 10), s = end, n = 1;
    if (*s || !n) die("manifest: size formula %s is not symbol[*num/den][+-offset]", formula);
    return (int)value;
}

/* The symbols of the frame's size formulas for a W x H frame: {W, H, w, h, wp, hp} (see frame_formula). */
static void frame_symbols(const Json *m, int W, int H, int sym[6]) {
    const Json *frame = jreq(m, "frame");
    const Json *ih_json = jget(frame, "internal_height");
    const int ih = ih_json && ih_json->type == J_NUM ? (int)ih_json->num : 0;
    /* round half to even, as Python's round */
    const int w = ih ? (int)fmax(1.0, rint((double)W * ih / H)) : W, h = ih ? ih : H;
    const int p = (int)jnum(jreq(m, "pad"), "multiple");
    if (w < p || h < p) die("the network's input %dx%d is smaller than the pad multiple %d", w, h, p);
    sym[0] = W, sym[1] = H, sym[2] = w, sym[3] = h, sym[4] = (w + p - 1) / p * p, sym[5] = (h + p - 1) / p * p;
}

/* Whether frame step st runs: not marked "skip", and its "when" (if any) holds; same: whether the network's
 * input has the frame's size, (w, h) == (W, H). */
static int step_runs(const Json *st, int same) {
    const Json *when = jget(st, "when");
    if (jget(st, "skip")) return 0;
    if (when) {
        const int at_frame_size = !strcmp(when->str, "(w, h) == (W, H)");
        if (!at_frame_size && strcmp(when->str, "(w, h) != (W, H)")) die("manifest: step condition %s", when->str);
        if (at_frame_size != same) return 0;
    }
    return 1;
}

/* The step's pass entry: a frame pass by name, or the network's pass at "index". */
static const Json *step_pass(const Json *m, const Json *step) {
    Json *name = jget(step, "frame_pass");
    if (!name) {
        const Json *passes = jreq(m, "passes");
        const int i = (int)jnum(step, "index");
        if (i < 0 || i >= passes->n) die("manifest: frame step index %d is not a pass", i);
        return passes->items[i];
    }
    const Json *passes = jreq(jreq(m, "frame"), "passes");
    for (int i = 0; i < passes->n; i++)
        if (!strcmp(jstr(passes->items[i], "name"), name->str)) return passes->items[i];
    die("manifest: frame step %s is no frame pass", name->str);
    return NULL;
}

/* The engine inputs this host feeds are depth and normal: a model that reads another (the back layer,
 * depth_back, of input version 4) is refused, never run with that texture left at zero. */
static void check_frame_inputs(const Json *frame) {
    const Json *inputs = jreq(frame, "inputs");
    for (int i = 0; i < inputs->n; i++)
        if (strcmp(inputs->keys[i], "depth") != 0 && strcmp(inputs->keys[i], "normal") != 0)
            die("the model reads the engine input \"%s\", which this host does not feed (it feeds depth and "
                "normal)", inputs->keys[i]);
}

/* The texels of the engine's input k (0: "depth", 1: "normal") with `lanes` floats a texel, px = W x H
 * pixels of gb (row 0 on top): depth in lane 0, or the unit normal in lanes 0-2 (non-finite values 0),
 * zero on background. */
static float *input_texels(const float *gb, size_t px, int k, int lanes) {
    float *data = xmalloc(sizeof(float) * (size_t)lanes * px);
    for (size_t i = 0; i < px; i++) {
        const float *g = gb + i * 5;
        if (!(g[4] >= 0.5f)) continue;
        float *texel = data + i * (size_t)lanes;
        if (k == 0) texel[0] = g[0];
        else for (int c = 0; c < 3 && c < lanes; c++) texel[c] = isfinite(g[1 + c]) ? g[1 + c] : 0.0f;
    }
    return data;
}

/* Writes one value of the FrameUniforms block: its member `name` at `offset`, as the camera gives it. */
static void uniform_member(unsigned char *block, size_t bytes, const char *name, size_t offset, int W, int H,
                           double radius, double yfov) {
    const double focal = 1.0 / tan(0.5 * yfov), p00 = focal / ((double)W / H), p11 = focal;
    float v[2];
    int flip = 0, n = 1;
    if (!strcmp(name, "u_proj")) v[0] = (float)p00, v[1] = (float)p11, n = 2;
    else if (!strcmp(name, "u_radius")) v[0] = (float)radius;
    else if (!strcmp(name, "u_pixels_per_unit")) v[0] = (float)(0.5 * H * p11);
    else if (!strcmp(name, "u_flip_y")) n = 0;  /* textures top row first */
    else die("manifest: FrameUniforms member %s is not one this host fills", name);
    const size_t size = n ? sizeof(float) * (size_t)n : sizeof flip;
    if (offset + size > bytes) die("manifest: FrameUniforms member %s lies outside the block", name);
    memcpy(block + offset, n ? (const void *)v : (const void *)&flip, size);
}

/* The FrameUniforms block of the frame section (frame.uniform_block), filled from the camera;
 * *bytes: its size. */
static unsigned char *frame_uniforms(const Json *frame, int W, int H, double radius, double yfov, size_t *bytes) {
    const Json *ub = jreq(frame, "uniform_block"), *members = jreq(ub, "members");
    const size_t ub_bytes = (size_t)jnum(ub, "bytes");
    unsigned char *block = xmalloc(ub_bytes);
    for (int k = 0; k < members->n; k++)
        uniform_member(block, ub_bytes, jstr(members->items[k], "name"), (size_t)jnum(members->items[k], "offset"),
                       W, H, radius, yfov);
    *bytes = ub_bytes;
    return block;
}

#endif /* NEURALAO_HOST_COMMON_H */
