/*
 * neuralao_vk: the reference Vulkan integration of a shipped screen-space AO export, in C; the Vulkan
 * counterpart of neuralao_host.c (OpenGL), with the same command line, files and timing line.
 *
 *   neuralao_vk EXPORT_DIR GBUFFER.f32 WIDTH HEIGHT RADIUS YFOV_DEG OUT.f32
 *
 * EXPORT_DIR   a shipped export (runtime/models/<name>, holding vulkan/manifest.json) or its vulkan/ folder
 * GBUFFER.f32  raw float32 little-endian, HEIGHT x WIDTH pixels, row 0 = the top row, 5 floats a pixel:
 *              linear camera-space depth z (> 0 in front of the camera, 0 on background),
 *              camera-space unit normal nx, ny, nz (OpenGL axes, facing the viewer), mask (>= 0.5 foreground);
 *              or the word "synthetic": a seeded wavy surface filling the frame (all foreground)
 * RADIUS       AO radius in scene units; YFOV_DEG the vertical field of view in degrees
 * OUT.f32      raw float32, HEIGHT x WIDTH, row 0 = the top row: AO in [0, 1], 1 on background
 *
 * The export's vulkan/manifest.json (format neuralao-vulkan-compute) must have a "frame" section: the
 * runner follows its "steps" as the GL host does (docs/engine-integration.md), with no CPU work between
 * passes, from the export's precompiled SPIR-V (each pass's spirv.file):
 *   1. every texture of frame.textures created at its size formula (W x H the frame, w x h the network's
 *      input, wp x hp those padded) as a 2-D array image in its format (RGBA32F, RGBA16F, R32F, R16F, R16:
 *      16-bit unsigned normalised, a hybrid's GTAO at fp16), usage
 *      SAMPLED | STORAGE, layout GENERAL throughout (the manifest's "vulkan" section);
 *   2. the engine's two inputs, "depth" and "normal" (row 0 = the top row, zero on background), copied in
 *      from a staging buffer (vkCmdCopyBufferToImage);
 *   3. the FrameUniforms block (frame.uniform_block) filled from the camera: u_proj = (P00, P11),
 *      u_radius = RADIUS, u_pixels_per_unit = 0.5 * H * P11, u_flip_y = 0 (textures top row first); each
 *      network pass with a PassUniforms block (u_flip_y) a 16-byte range of its own holding u_flip_y = 0;
 *      weights.bin in one storage buffer;
 *   4. each step in order (those marked "skip" left out, of those with a "when" the one whose condition
 *      holds): one compute pipeline per SPIR-V file, one descriptor set per step (set 0, the pass's
 *      "bindings": sampled images, its storage image, its range of the weights at params.offset, its
 *      uniform buffer), its dispatch.groups, then the manifest's barrier (COMPUTE -> COMPUTE,
 *      SHADER_WRITE -> SHADER_READ; SHADER_WRITE too, for a later pass writing an image again);
 *   5. only the output texture (frame.output, the AO) copied back.
 * A weight range whose offset the device cannot bind (minStorageBufferOffsetAlignment above the manifest's
 * weights.range_alignment) is moved to an aligned offset of a repacked copy of weights.bin.
 *
 * Timing (bench/gpu.sh): with NEURALAO_HOST_REPEATS=N set, after the frame N timed submissions of the whole
 * frame (every step), of its GTAO steps (f_gtao, f_gtao_blur; a hybrid's) and of its network steps, each
 * between two vkCmdWriteTimestamp (ms by the device's timestampPeriod; -1 where the queue has no timestamps)
 * and on the wall clock from vkQueueSubmit to its fence. One JSON line goes to stdout, medians in ms
 * (-1: not run): {"renderer" (the device's name), "api": "vulkan", "version" (Vulkan version and driver),
 * "width", "height", "repeats", "path": "frame", "frame_ms", "network_ms", "gtao_ms", "ssao_ms" (-1: the
 * SSAO baseline runs in the GL host only), the same with _wall_ms, "passes"}.
 *
 * Device: the first physical device with a compute queue, or with NEURALAO_VK_DEVICE=TEXT the first whose
 * name contains TEXT. Features are enabled as the passes' SPIR-V declares them (shaderFloat16 for fp16
 * arithmetic, shaderStorageImageExtendedFormats for the R16F and R16 storage images of fp16); a device without one, or
 * without a format's storage support, is an error naming it.
 */
#define _POSIX_C_SOURCE 200809L /* clock_gettime */
#include <stdint.h>
#include <vulkan/vulkan.h>

#define HOST_NAME "neuralao_vk"
#include "host_common.h"

static void vk_check(VkResult r, const char *what) {
    if (r != VK_SUCCESS) die("%s failed (VkResult %d)", what, (int)r);
}
#define VK(call) vk_check((call), #call)

static VkDeviceSize align_up(VkDeviceSize v, VkDeviceSize a) { return a > 1 ? (v + a - 1) / a * a : v; }

/* ------------------------------------------------------------------ half floats (fp16 exports) */

static uint16_t float_to_half(float f) { /* round to nearest even */
    uint32_t x;
    memcpy(&x, &f, 4);
    const uint32_t sign = (x >> 16) & 0x8000u, exp = (x >> 23) & 0xffu, mant = x & 0x7fffffu;
    if (exp == 0xff) return (uint16_t)(sign | 0x7c00u | (mant ? 0x200u : 0u)); /* inf, NaN */
    const int e = (int)exp - 127 + 15;
    if (e >= 31) return (uint16_t)(sign | 0x7c00u);
    if (e <= 0) { /* subnormal or zero */
        if (e < -10) return (uint16_t)sign;
        const uint32_t m = mant | 0x800000u, shift = (uint32_t)(14 - e);
        uint32_t h = m >> shift;
        const uint32_t rest = m & ((1u << shift) - 1u), half = 1u << (shift - 1u);
        if (rest > half || (rest == half && (h & 1u))) h++;
        return (uint16_t)(sign | h);
    }
    uint32_t h = ((uint32_t)e << 10) | (mant >> 13);
    const uint32_t rest = mant & 0x1fffu;
    if (rest > 0x1000u || (rest == 0x1000u && (h & 1u))) h++; /* may carry into the exponent: still right */
    return (uint16_t)(sign | h);
}

static float half_to_float(uint16_t h) {
    const uint32_t sign = (uint32_t)(h & 0x8000u) << 16, exp = (h >> 10) & 0x1fu, mant = h & 0x3ffu;
    uint32_t x;
    if (exp == 0x1f) x = sign | 0x7f800000u | (mant << 13);
    else if (exp) x = sign | ((exp + 112u) << 23) | (mant << 13);
    else if (!mant) x = sign;
    else { /* subnormal: normalise */
        int e = -1;
        uint32_t m = mant;
        do e++, m <<= 1; while (!(m & 0x400u));
        x = sign | ((uint32_t)(112 - e) << 23) | ((m & 0x3ffu) << 13);
    }
    float f;
    memcpy(&f, &x, 4);
    return f;
}

/* ------------------------------------------------------------------ device */

/* SPIR-V capabilities the passes may declare beyond Shader, and the device feature each needs. */
enum { CAP_FLOAT16 = 9, CAP_FLOAT64 = 10, CAP_INT64 = 11, CAP_INT16 = 22, CAP_EXTENDED_FORMATS = 49,
       CAP_READ_WITHOUT_FORMAT = 55, CAP_WRITE_WITHOUT_FORMAT = 56 };

typedef struct {
    int float16, float64, int64, int16, extended_formats, read_without_format, write_without_format;
} Needs;

typedef struct {
    VkInstance instance;
    VkPhysicalDevice phys;
    VkDevice dev;
    VkQueue queue;
    uint32_t family, timestamp_bits;
    uint32_t instance_version; /* the Vulkan version the instance was created for: 1.2 where the loader has it */
    VkPhysicalDeviceProperties props;
    VkPhysicalDeviceMemoryProperties mem;
    VkCommandPool pool;
    VkFence fence;
    char version[600]; /* "Vulkan 1.3.230, <driver name> <driver info>" */
} Gpu;

static void create_instance(Gpu *g) {
    uint32_t loader = VK_API_VERSION_1_0;
    PFN_vkEnumerateInstanceVersion enumerate_version =
        (PFN_vkEnumerateInstanceVersion)vkGetInstanceProcAddr(NULL, "vkEnumerateInstanceVersion");
    if (enumerate_version) enumerate_version(&loader);
    g->instance_version = loader >= VK_API_VERSION_1_2 ? VK_API_VERSION_1_2 : VK_API_VERSION_1_0;
    const VkApplicationInfo app = {
        .sType = VK_STRUCTURE_TYPE_APPLICATION_INFO,
        .pApplicationName = HOST_NAME,
        .apiVersion = g->instance_version,
    };
    const VkInstanceCreateInfo info = {.sType = VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO, .pApplicationInfo = &app};
    const VkResult r = vkCreateInstance(&info, NULL, &g->instance);
    if (r != VK_SUCCESS) die("no Vulkan driver (vkCreateInstance: VkResult %d; Debian: mesa-vulkan-drivers)", (int)r);
}

static int compute_family(VkPhysicalDevice phys, uint32_t *family, uint32_t *timestamp_bits) {
    uint32_t n = 0;
    vkGetPhysicalDeviceQueueFamilyProperties(phys, &n, NULL);
    VkQueueFamilyProperties *q = xmalloc(sizeof *q * (n ? n : 1));
    vkGetPhysicalDeviceQueueFamilyProperties(phys, &n, q);
    int found = 0;
    for (uint32_t i = 0; i < n && !found; i++)
        if (q[i].queueFlags & VK_QUEUE_COMPUTE_BIT) *family = i, *timestamp_bits = q[i].timestampValidBits, found = 1;
    free(q);
    return found;
}

/* The first physical device with a compute queue (whose name contains NEURALAO_VK_DEVICE, when set). */
static void pick_device(Gpu *g) {
    uint32_t n = 0;
    VK(vkEnumeratePhysicalDevices(g->instance, &n, NULL));
    if (!n) die("no Vulkan device (Debian: mesa-vulkan-drivers has lavapipe)");
    VkPhysicalDevice *devs = xmalloc(sizeof *devs * n);
    VK(vkEnumeratePhysicalDevices(g->instance, &n, devs));
    const char *want = getenv("NEURALAO_VK_DEVICE");
    char seen[1024] = "";
    for (uint32_t i = 0; i < n; i++) {
        VkPhysicalDeviceProperties p;
        vkGetPhysicalDeviceProperties(devs[i], &p);
        if (strlen(seen) + strlen(p.deviceName) + 4 < sizeof seen)
            strcat(strcat(seen, *seen ? ", " : ""), p.deviceName);
        if (want && !strstr(p.deviceName, want)) continue;
        if (!compute_family(devs[i], &g->family, &g->timestamp_bits)) continue;
        g->phys = devs[i], g->props = p;
        free(devs);
        vkGetPhysicalDeviceMemoryProperties(g->phys, &g->mem);
        return;
    }
    if (want) die("no Vulkan device with a compute queue is named like NEURALAO_VK_DEVICE=%s (devices: %s)", want, seen);
    die("no Vulkan device has a compute queue (devices: %s)", seen);
}

/* The Vulkan version and the driver's name and version (VkPhysicalDeviceDriverProperties, Vulkan 1.2). */
static void describe_driver(Gpu *g) {
    const uint32_t v = g->props.apiVersion;
    int n = snprintf(g->version, sizeof g->version, "Vulkan %u.%u.%u", VK_API_VERSION_MAJOR(v), VK_API_VERSION_MINOR(v),
                     VK_API_VERSION_PATCH(v));
    if (v >= VK_API_VERSION_1_2 && g->instance_version >= VK_API_VERSION_1_2) {
        VkPhysicalDeviceDriverProperties driver = {.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_DRIVER_PROPERTIES};
        VkPhysicalDeviceProperties2 p2 = {.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2, .pNext = &driver};
        vkGetPhysicalDeviceProperties2(g->phys, &p2);
        snprintf(g->version + n, sizeof g->version - (size_t)n, ", %s %s", driver.driverName, driver.driverInfo);
    } else {
        snprintf(g->version + n, sizeof g->version - (size_t)n, ", driver 0x%08x", g->props.driverVersion);
    }
}

/* The logical device with the features `need` lists (each checked against the device's). */
static void create_device(Gpu *g, const Needs *need) {
    VkPhysicalDeviceFeatures have;
    vkGetPhysicalDeviceFeatures(g->phys, &have);
    VkPhysicalDeviceFeatures on = {0};
    const struct { int needed; VkBool32 has, *enable; const char *name; } base[] = {
        {need->float64, have.shaderFloat64, &on.shaderFloat64, "shaderFloat64"},
        {need->int64, have.shaderInt64, &on.shaderInt64, "shaderInt64"},
        {need->int16, have.shaderInt16, &on.shaderInt16, "shaderInt16"},
        {need->extended_formats, have.shaderStorageImageExtendedFormats, &on.shaderStorageImageExtendedFormats,
         "shaderStorageImageExtendedFormats (R16F and R16 storage images)"},
        {need->read_without_format, have.shaderStorageImageReadWithoutFormat,
         &on.shaderStorageImageReadWithoutFormat, "shaderStorageImageReadWithoutFormat"},
        {need->write_without_format, have.shaderStorageImageWriteWithoutFormat,
         &on.shaderStorageImageWriteWithoutFormat, "shaderStorageImageWriteWithoutFormat"},
    };
    for (size_t i = 0; i < sizeof base / sizeof base[0]; i++) {
        if (!base[i].needed) continue;
        if (!base[i].has) die("the passes need %s, which %s lacks", base[i].name, g->props.deviceName);
        *base[i].enable = VK_TRUE;
    }
    VkPhysicalDeviceShaderFloat16Int8Features f16 = {.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SHADER_FLOAT16_INT8_FEATURES};
    if (need->float16) { /* fp16 arithmetic: a Vulkan 1.2 feature */
        if (g->props.apiVersion < VK_API_VERSION_1_2 || g->instance_version < VK_API_VERSION_1_2)
            die("the fp16 passes need shaderFloat16: %s (or the Vulkan loader) is below Vulkan 1.2", g->props.deviceName);
        VkPhysicalDeviceShaderFloat16Int8Features query = {.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SHADER_FLOAT16_INT8_FEATURES};
        VkPhysicalDeviceFeatures2 f2 = {.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2, .pNext = &query};
        vkGetPhysicalDeviceFeatures2(g->phys, &f2);
        if (!query.shaderFloat16) die("the fp16 passes need shaderFloat16, which %s lacks", g->props.deviceName);
        f16.shaderFloat16 = VK_TRUE;
    }
    const float priority = 1.0f;
    const VkDeviceQueueCreateInfo queue = {.sType = VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO,
                                           .queueFamilyIndex = g->family, .queueCount = 1,
                                           .pQueuePriorities = &priority};
    const VkDeviceCreateInfo info = {.sType = VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO, .pNext = need->float16 ? &f16 : NULL,
                                     .queueCreateInfoCount = 1, .pQueueCreateInfos = &queue,
                                     .pEnabledFeatures = &on};
    VK(vkCreateDevice(g->phys, &info, NULL, &g->dev));
    vkGetDeviceQueue(g->dev, g->family, 0, &g->queue);
    const VkCommandPoolCreateInfo pool = {.sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO,
                                          .queueFamilyIndex = g->family};
    VK(vkCreateCommandPool(g->dev, &pool, NULL, &g->pool));
    const VkFenceCreateInfo fence = {.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
    VK(vkCreateFence(g->dev, &fence, NULL, &g->fence));
}

/* Memory of `req` with the properties `want` (else any of its types when `fallback`). */
static VkDeviceMemory allocate(const Gpu *g, VkMemoryRequirements req, VkMemoryPropertyFlags want, int fallback) {
    for (int pass = 0; pass < 2; pass++) {
        const VkMemoryPropertyFlags flags = pass ? 0 : want;
        if (pass && !fallback) break;
        for (uint32_t i = 0; i < g->mem.memoryTypeCount; i++) {
            if (!(req.memoryTypeBits & (1u << i)) || (g->mem.memoryTypes[i].propertyFlags & flags) != flags) continue;
            const VkMemoryAllocateInfo info = {.sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO,
                                               .allocationSize = req.size, .memoryTypeIndex = i};
            VkDeviceMemory m;
            VK(vkAllocateMemory(g->dev, &info, NULL, &m));
            return m;
        }
    }
    die("no Vulkan memory type with properties 0x%x for %llu bytes", (unsigned)want, (unsigned long long)req.size);
    return VK_NULL_HANDLE;
}

typedef struct {
    VkBuffer buf;
    VkDeviceMemory mem;
    void *map; /* host-visible buffers: their mapping */
} Buffer;

static Buffer make_buffer(const Gpu *g, VkDeviceSize size, VkBufferUsageFlags usage, int host) {
    Buffer b = {0};
    const VkBufferCreateInfo info = {.sType = VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO, .size = size ? size : 16,
                                     .usage = usage, .sharingMode = VK_SHARING_MODE_EXCLUSIVE};
    VK(vkCreateBuffer(g->dev, &info, NULL, &b.buf));
    VkMemoryRequirements req;
    vkGetBufferMemoryRequirements(g->dev, b.buf, &req);
    b.mem = host ? allocate(g, req, VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT, 0)
                 : allocate(g, req, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT, 1);
    VK(vkBindBufferMemory(g->dev, b.buf, b.mem, 0));
    if (host) VK(vkMapMemory(g->dev, b.mem, 0, VK_WHOLE_SIZE, 0, &b.map));
    return b;
}

/* ------------------------------------------------------------------ textures */

typedef struct {
    const char *id;
    VkImage image;
    VkDeviceMemory mem;
    VkImageView view;
    VkFormat format;
    int w, h, layers, lanes, channel; /* lanes: 1 (R) or 4 (RGBA); channel: CH_* */
} Texture;

/* How a texture's channels are stored: float32, float16, 16-bit unsigned normalised ([0, 1] in 65535 steps). */
enum { CH_FLOAT, CH_HALF, CH_UNORM16 };

static void texture_format(const char *name, Texture *t) {
    static const struct { const char *name; VkFormat format; int lanes, channel; } formats[] = {
        {"RGBA32F", VK_FORMAT_R32G32B32A32_SFLOAT, 4, CH_FLOAT}, {"RGBA16F", VK_FORMAT_R16G16B16A16_SFLOAT, 4, CH_HALF},
        {"R32F", VK_FORMAT_R32_SFLOAT, 1, CH_FLOAT},             {"R16F", VK_FORMAT_R16_SFLOAT, 1, CH_HALF},
        {"R16", VK_FORMAT_R16_UNORM, 1, CH_UNORM16},
    };
    for (size_t i = 0; i < sizeof formats / sizeof formats[0]; i++)
        if (!strcmp(name, formats[i].name)) {
            t->format = formats[i].format, t->lanes = formats[i].lanes, t->channel = formats[i].channel;
            return;
        }
    die("manifest: texture format %s is not one this runner allocates", name);
}

static size_t texel_bytes(const Texture *t) { return (size_t)t->lanes * (t->channel == CH_FLOAT ? 4 : 2); }

/* n floats into channels stored as `channel` (a normalised one clamped to [0, 1], rounded to the nearest step). */
static void store_channels(int channel, const float *src, size_t n, void *dst) {
    if (channel == CH_FLOAT) memcpy(dst, src, n * sizeof(float));
    else if (channel == CH_HALF)
        for (size_t i = 0; i < n; i++) ((uint16_t *)dst)[i] = float_to_half(src[i]);
    else
        for (size_t i = 0; i < n; i++) {
            const float v = src[i] > 0.0f ? (src[i] < 1.0f ? src[i] : 1.0f) : 0.0f; /* NaN: 0 */
            ((uint16_t *)dst)[i] = (uint16_t)(v * 65535.0f + 0.5f);
        }
}

/* Channel i of data stored as `channel`, as a float. */
static float load_channel(int channel, const void *data, size_t i) {
    if (channel == CH_FLOAT) return ((const float *)data)[i];
    const uint16_t v = ((const uint16_t *)data)[i];
    return channel == CH_HALF ? half_to_float(v) : (float)v / 65535.0f;
}

static Texture *find_texture(Texture *t, int n, const char *id) {
    for (int i = 0; i < n; i++) if (!strcmp(t[i].id, id)) return &t[i];
    die("manifest: no texture %s", id);
    return NULL;
}

static void create_texture(const Gpu *g, Texture *t, VkImageUsageFlags extra_usage) {
    VkFormatProperties fp;
    vkGetPhysicalDeviceFormatProperties(g->phys, t->format, &fp);
    const VkFormatFeatureFlags need = VK_FORMAT_FEATURE_STORAGE_IMAGE_BIT | VK_FORMAT_FEATURE_SAMPLED_IMAGE_BIT;
    if ((fp.optimalTilingFeatures & need) != need)
        die("%s cannot use format %d as a sampled and storage image (texture %s)", g->props.deviceName, (int)t->format, t->id);
    const VkPhysicalDeviceLimits *lim = &g->props.limits;
    if ((uint32_t)t->w > lim->maxImageDimension2D || (uint32_t)t->h > lim->maxImageDimension2D ||
        (uint32_t)t->layers > lim->maxImageArrayLayers)
        die("texture %s is %dx%dx%d, beyond %s's image limits", t->id, t->w, t->h, t->layers, g->props.deviceName);
    const VkImageCreateInfo info = {
        .sType = VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO, .imageType = VK_IMAGE_TYPE_2D, .format = t->format,
        .extent = {(uint32_t)t->w, (uint32_t)t->h, 1}, .mipLevels = 1, .arrayLayers = (uint32_t)t->layers,
        .samples = VK_SAMPLE_COUNT_1_BIT, .tiling = VK_IMAGE_TILING_OPTIMAL,
        .usage = VK_IMAGE_USAGE_SAMPLED_BIT | VK_IMAGE_USAGE_STORAGE_BIT | extra_usage,
        .sharingMode = VK_SHARING_MODE_EXCLUSIVE, .initialLayout = VK_IMAGE_LAYOUT_UNDEFINED,
    };
    VK(vkCreateImage(g->dev, &info, NULL, &t->image));
    VkMemoryRequirements req;
    vkGetImageMemoryRequirements(g->dev, t->image, &req);
    t->mem = allocate(g, req, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT, 1);
    VK(vkBindImageMemory(g->dev, t->image, t->mem, 0));
    const VkImageViewCreateInfo view = {
        .sType = VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO, .image = t->image,
        .viewType = VK_IMAGE_VIEW_TYPE_2D_ARRAY, .format = t->format,
        .subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, (uint32_t)t->layers},
    };
    VK(vkCreateImageView(g->dev, &view, NULL, &t->view));
}

/* ------------------------------------------------------------------ passes and steps */

typedef struct {
    const char *file;             /* the SPIR-V file: pipelines are cached by it */
    uint32_t *words;
    size_t n_words;
    VkDescriptorSetLayout dsl;
    VkPipelineLayout layout;
    VkPipeline pipeline;
} Pipeline;

enum { STEP_OTHER, STEP_GTAO, STEP_NETWORK }; /* what the timed runs time apart */

typedef struct {
    const Json *pass;
    Pipeline *pipe;
    VkDescriptorSet set;
    uint32_t groups[3];
    int kind;                       /* STEP_* */
    VkDeviceSize weights_offset;    /* its range in the weights buffer (repacked when the device needs it) */
    VkDeviceSize pass_ubo_offset;   /* its PassUniforms range in the uniform buffer (when it has one) */
} Step;

/* Capabilities a SPIR-V module declares (OpCapability), added to *need. */
static void scan_capabilities(const uint32_t *w, size_t n, const char *file, Needs *need) {
    if (n < 5 || w[0] != 0x07230203u) die("%s is not SPIR-V", file);
    for (size_t i = 5; i < n;) {
        const uint32_t count = w[i] >> 16, op = w[i] & 0xffffu;
        if (!count || i + count > n) die("%s: malformed SPIR-V", file);
        if (op == 17 && count >= 2) { /* OpCapability */
            switch (w[i + 1]) {
                case CAP_FLOAT16: need->float16 = 1; break;
                case CAP_FLOAT64: need->float64 = 1; break;
                case CAP_INT64: need->int64 = 1; break;
                case CAP_INT16: need->int16 = 1; break;
                case CAP_EXTENDED_FORMATS: need->extended_formats = 1; break;
                case CAP_READ_WITHOUT_FORMAT: need->read_without_format = 1; break;
                case CAP_WRITE_WITHOUT_FORMAT: need->write_without_format = 1; break;
                default: break;
            }
        }
        i += count;
    }
}

static Pipeline *find_pipeline(Pipeline *pipes, int *n_pipes, const char *dir, const Json *pass, Needs *need) {
    const char *file = jstr(jreq(pass, "spirv"), "file");
    for (int i = 0; i < *n_pipes; i++) if (!strcmp(pipes[i].file, file)) return &pipes[i];
    Pipeline *p = &pipes[(*n_pipes)++];
    char path[4200];
    snprintf(path, sizeof path, "%s/%s", dir, file);
    size_t bytes;
    p->file = file;
    p->words = (uint32_t *)read_file(path, &bytes);
    if (bytes % 4) die("%s is not SPIR-V (%zu bytes)", path, bytes);
    p->n_words = bytes / 4;
    scan_capabilities(p->words, p->n_words, path, need);
    return p;
}

static VkDescriptorType descriptor_type(const char *kind) {
    if (!strcmp(kind, "sampled_image")) return VK_DESCRIPTOR_TYPE_SAMPLED_IMAGE;
    if (!strcmp(kind, "storage_image")) return VK_DESCRIPTOR_TYPE_STORAGE_IMAGE;
    if (!strcmp(kind, "storage_buffer")) return VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    if (!strcmp(kind, "uniform_buffer")) return VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER;
    die("manifest: binding kind %s is not one this runner binds", kind);
    return VK_DESCRIPTOR_TYPE_MAX_ENUM;
}

/* The descriptor set layout (from the pass's "bindings"), pipeline layout and compute pipeline. */
static void build_pipeline(const Gpu *g, Pipeline *p, const Json *pass, const char *entry, int set) {
    const Json *bindings = jreq(pass, "bindings");
    VkDescriptorSetLayoutBinding *b = xmalloc(sizeof *b * (size_t)(bindings->n ? bindings->n : 1));
    for (int i = 0; i < bindings->n; i++) {
        const Json *x = bindings->items[i];
        if ((int)jnum(x, "set") != set) die("pass %s binds set %.0f, the manifest's set is %d", jstr(pass, "name"), jnum(x, "set"), set);
        b[i] = (VkDescriptorSetLayoutBinding){.binding = (uint32_t)jnum(x, "binding"),
                                              .descriptorType = descriptor_type(jstr(x, "kind")),
                                              .descriptorCount = 1, .stageFlags = VK_SHADER_STAGE_COMPUTE_BIT};
    }
    const VkDescriptorSetLayoutCreateInfo dsl = {.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO,
                                                 .bindingCount = (uint32_t)bindings->n, .pBindings = b};
    VK(vkCreateDescriptorSetLayout(g->dev, &dsl, NULL, &p->dsl));
    free(b);
    const VkPipelineLayoutCreateInfo layout = {.sType = VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO,
                                               .setLayoutCount = 1, .pSetLayouts = &p->dsl};
    VK(vkCreatePipelineLayout(g->dev, &layout, NULL, &p->layout));
    const VkShaderModuleCreateInfo sm = {.sType = VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO,
                                         .codeSize = p->n_words * 4, .pCode = p->words};
    VkShaderModule module;
    VK(vkCreateShaderModule(g->dev, &sm, NULL, &module));
    const VkComputePipelineCreateInfo info = {
        .sType = VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO,
        .stage = {.sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO, .stage = VK_SHADER_STAGE_COMPUTE_BIT,
                  .module = module, .pName = entry},
        .layout = p->layout,
    };
    const VkResult r = vkCreateComputePipelines(g->dev, VK_NULL_HANDLE, 1, &info, NULL, &p->pipeline);
    if (r != VK_SUCCESS) die("%s: vkCreateComputePipelines failed (VkResult %d)", p->file, (int)r);
    vkDestroyShaderModule(g->dev, module, NULL);
}

/* One count of dispatch.groups: "ceil(width(T) / n)", "ceil(height(T) / n)", "layers(T) / n[ = k]" or a
 * number, with T's size at this frame. */
static uint32_t group_count(const char *formula, Texture *tex, int n_tex, const char *pass) {
    char what[16], id[128];
    long div = 0, stated = -1;
    int used = 0;
    if (sscanf(formula, "ceil(%15[a-z](%127[^)]) / %ld)%n", what, id, &div, &used) == 3 && !formula[used] && div > 0) {
        const Texture *t = find_texture(tex, n_tex, id);
        if (!strcmp(what, "width")) return (uint32_t)((t->w + div - 1) / div);
        if (!strcmp(what, "height")) return (uint32_t)((t->h + div - 1) / div);
    } else if (sscanf(formula, "layers(%127[^)]) / %ld%n", id, &div, &used) == 2 && div > 0) {
        const Texture *t = find_texture(tex, n_tex, id);
        const char *rest = formula + used;
        int tail = 0;
        if (*rest && (sscanf(rest, " = %ld%n", &stated, &tail) != 1 || rest[tail]))
            die("pass %s: dispatch count %s is not one this runner reads", pass, formula);
        if (t->layers % div || (stated >= 0 && stated != t->layers / div))
            die("pass %s: dispatch count %s does not fit texture %s's %d layers", pass, formula, id, t->layers);
        return (uint32_t)(t->layers / div);
    } else {
        char *end;
        const long v = strtol(formula, &end, 10);
        if (end != formula && !*end && v > 0) return (uint32_t)v;
    }
    die("pass %s: dispatch count %s is not one this runner reads", pass, formula);
    return 0;
}

/* ------------------------------------------------------------------ the frame */

typedef struct {
    Gpu g;
    Texture *tex;
    int n_tex;
    Pipeline *pipes;
    int n_pipes;
    Step *steps;
    int n_steps;
    Buffer weights, ubo;
    VkDescriptorPool dpool;
    VkQueryPool queries;
} Frame;

/* Barrier after each dispatch (the manifest's "barrier"): the next pass reads what this one wrote; its
 * SHADER_WRITE also orders a later pass writing an image an earlier one wrote. */
static void compute_barrier(VkCommandBuffer cmd, VkPipelineStageFlags src_stage, VkAccessFlags src,
                            VkPipelineStageFlags dst_stage, VkAccessFlags dst) {
    const VkMemoryBarrier b = {.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER, .srcAccessMask = src, .dstAccessMask = dst};
    vkCmdPipelineBarrier(cmd, src_stage, dst_stage, 0, 1, &b, 0, NULL, 0, NULL);
}

static void record_steps(const Frame *f, VkCommandBuffer cmd, int kind) {
    for (int i = 0; i < f->n_steps; i++) {
        const Step *s = &f->steps[i];
        if (kind >= 0 && s->kind != kind) continue;
        vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, s->pipe->pipeline);
        vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, s->pipe->layout, 0, 1, &s->set, 0, NULL);
        vkCmdDispatch(cmd, s->groups[0], s->groups[1], s->groups[2]);
        compute_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                        VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT);
    }
}

static VkCommandBuffer begin_commands(const Gpu *g) {
    const VkCommandBufferAllocateInfo info = {.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO,
                                              .commandPool = g->pool, .level = VK_COMMAND_BUFFER_LEVEL_PRIMARY,
                                              .commandBufferCount = 1};
    VkCommandBuffer cmd;
    VK(vkAllocateCommandBuffers(g->dev, &info, &cmd));
    const VkCommandBufferBeginInfo begin = {.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
    VK(vkBeginCommandBuffer(cmd, &begin));
    return cmd;
}

/* Submits cmd and waits for it; returns the wall-clock ms from the submission to its fence. */
static double submit_and_wait(const Gpu *g, VkCommandBuffer cmd) {
    const VkSubmitInfo submit = {.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO, .commandBufferCount = 1, .pCommandBuffers = &cmd};
    const double start = wall_ms();
    VK(vkQueueSubmit(g->queue, 1, &submit, g->fence));
    VK(vkWaitForFences(g->dev, 1, &g->fence, VK_TRUE, UINT64_MAX));
    const double wall = wall_ms() - start;
    VK(vkResetFences(g->dev, 1, &g->fence));
    return wall;
}

/* Medians of N timed submissions of the steps of one kind (all: kind < 0), between two timestamps (*ms, -1
 * without timestamps) and on the wall clock (*wall); both stay -1 when the frame has none of that kind. */
static void time_steps(const Frame *f, int kind, int repeats, double *ms, double *wall) {
    int any = kind < 0;
    for (int i = 0; i < f->n_steps; i++) any |= f->steps[i].kind == kind;
    if (!any || repeats < 1) return;
    const Gpu *g = &f->g;
    VkCommandBuffer cmd = begin_commands(g);
    /* what the previous submission wrote is visible to this one's passes */
    compute_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                    VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT);
    if (f->queries) {
        vkCmdResetQueryPool(cmd, f->queries, 0, 2);
        vkCmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, f->queries, 0);
    }
    record_steps(f, cmd, kind);
    if (f->queries) vkCmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, f->queries, 1);
    VK(vkEndCommandBuffer(cmd));
    double *runs = xmalloc(sizeof(double) * (size_t)repeats * 2), *walls = runs + repeats;
    const uint64_t mask = g->timestamp_bits >= 64 ? UINT64_MAX : (1ull << g->timestamp_bits) - 1;
    for (int run = 0; run < repeats; run++) {
        walls[run] = submit_and_wait(g, cmd);
        runs[run] = -1;
        if (f->queries) {
            uint64_t t[2];
            VK(vkGetQueryPoolResults(g->dev, f->queries, 0, 2, sizeof t, t, sizeof t[0],
                                     VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT));
            runs[run] = (double)((t[1] - t[0]) & mask) * g->props.limits.timestampPeriod * 1e-6;
        }
    }
    *ms = f->queries ? median(runs, repeats) : -1, *wall = median(walls, repeats);
    free(runs);
    vkFreeCommandBuffers(g->dev, g->pool, 1, &cmd);
}

/* Fills the uniform block of network pass p (PassUniforms): u_flip_y = 0, the frame's textures top row
 * first; the frame sets no other uniform (its radius pass is skipped: f_network_radius writes that). */
static void pass_uniforms(const Json *p, unsigned char *block, size_t room) {
    const Json *ub = jreq(p, "uniform_block"), *members = jreq(ub, "members");
    if ((size_t)jnum(ub, "bytes") > room) die("pass %s: its uniform block is larger than %zu bytes", jstr(p, "name"), room);
    for (int k = 0; k < members->n; k++) {
        const char *name = jstr(members->items[k], "name");
        if (strcmp(name, "u_flip_y")) die("pass %s: the frame sets no uniform %s", jstr(p, "name"), name);
        const int32_t flip = 0;
        memcpy(block + (size_t)jnum(members->items[k], "offset"), &flip, sizeof flip);
    }
}

/* The whole frame from the manifest's "frame" section (see the header, steps 1-5). gb: H x W x 5 floats,
 * row 0 on top. Returns the AO, H x W, row 0 on top. */
static float *run_frame(const Json *m, const char *dir, const float *gb, int W, int H, double radius, double yfov,
                        int repeats, double timing[6], int *n_passes, char *renderer, size_t renderer_size,
                        char *version, size_t version_size) {
    Frame f = {0};
    Gpu *g = &f.g;
    const Json *frame = jreq(m, "frame");
    check_frame_inputs(frame);
    int sym[6];
    frame_symbols(m, W, H, sym);

    /* the textures' sizes and formats, the steps that run at this size and their SPIR-V */
    const Json *tex_json = jreq(frame, "textures");
    f.n_tex = tex_json->n;
    f.tex = xmalloc(sizeof(Texture) * (size_t)(f.n_tex ? f.n_tex : 1));
    for (int i = 0; i < f.n_tex; i++) {
        const Json *t = tex_json->items[i];
        Texture *x = &f.tex[i];
        x->id = tex_json->keys[i];
        x->w = frame_formula(jstr(t, "width"), sym), x->h = frame_formula(jstr(t, "height"), sym);
        x->layers = (int)jnum(t, "layers");
        texture_format(jstr(t, "format"), x);
        if (x->w < 1 || x->h < 1 || x->layers < 1) die("texture %s is %dx%dx%d", x->id, x->w, x->h, x->layers);
    }
    const Texture *net_in = find_texture(f.tex, f.n_tex, jstr(jreq(m, "input"), "texture"));
    const int same = net_in->w == W && net_in->h == H;
    const Json *steps = jreq(frame, "steps");
    const Json *vk = jget(m, "vulkan"), *spirv = jget(m, "spirv");
    const int set = vk && jget(vk, "descriptor_set") ? (int)jnum(vk, "descriptor_set") : 0;
    const char *entry = spirv && jget(spirv, "entry_point") ? jstr(spirv, "entry_point") : "main";
    f.steps = xmalloc(sizeof(Step) * (size_t)(steps->n ? steps->n : 1));
    f.pipes = xmalloc(sizeof(Pipeline) * (size_t)(steps->n ? steps->n : 1));
    Needs need = {0};
    for (int k = 0; k < steps->n; k++) {
        if (!step_runs(steps->items[k], same)) continue;
        Step *s = &f.steps[f.n_steps++];
        s->pass = step_pass(m, steps->items[k]);
        s->pipe = find_pipeline(f.pipes, &f.n_pipes, dir, s->pass, &need);
        const Json *groups = jreq(jreq(s->pass, "dispatch"), "groups");
        if (groups->n != 3) die("pass %s: dispatch.groups has %d counts", jstr(s->pass, "name"), groups->n);
        for (int a = 0; a < 3; a++) {
            if (groups->items[a]->type != J_STR) die("pass %s: dispatch.groups holds a non-string", jstr(s->pass, "name"));
            s->groups[a] = group_count(groups->items[a]->str, f.tex, f.n_tex, jstr(s->pass, "name"));
        }
        const char *name = jstr(s->pass, "name");
        s->kind = !jget(s->pass, "stage") ? STEP_NETWORK : !strncmp(name, "f_gtao", 6) ? STEP_GTAO : STEP_OTHER;
    }

    /* the device, with the features the passes declare */
    create_instance(g);
    pick_device(g);
    create_device(g, &need);
    describe_driver(g);
    snprintf(renderer, renderer_size, "%s", g->props.deviceName);
    snprintf(version, version_size, "%s", g->version);
    const VkPhysicalDeviceLimits *lim = &g->props.limits;
    for (int i = 0; i < f.n_steps; i++)
        for (int a = 0; a < 3; a++)
            if (f.steps[i].groups[a] > lim->maxComputeWorkGroupCount[a])
                die("pass %s dispatches %u groups along axis %d, beyond the device's %u", jstr(f.steps[i].pass, "name"),
                    f.steps[i].groups[a], a, lim->maxComputeWorkGroupCount[a]);

    /* 1. the textures */
    const char *output = jstr(frame, "output");
    for (int i = 0; i < f.n_tex; i++) {
        Texture *x = &f.tex[i];
        const int input = !strcmp(x->id, "depth") || !strcmp(x->id, "normal");
        create_texture(g, x, input ? VK_IMAGE_USAGE_TRANSFER_DST_BIT
                             : !strcmp(x->id, output) ? VK_IMAGE_USAGE_TRANSFER_SRC_BIT : 0);
    }

    /* the weights: each pass's range at its offset, or at the next offset the device can bind */
    size_t w_bytes;
    char *weights = read_weights(m, dir, &w_bytes);
    const VkDeviceSize salign = lim->minStorageBufferOffsetAlignment;
    int repack = 0;
    for (int i = 0; i < f.n_steps; i++) {
        const Json *params = jget(f.steps[i].pass, "params");
        if (!params) continue;
        const VkDeviceSize off = (VkDeviceSize)jnum(params, "offset"), bytes = (VkDeviceSize)jnum(params, "bytes");
        if (off + bytes > w_bytes) die("pass %s: its weights lie outside %s", jstr(f.steps[i].pass, "name"), "weights.bin");
        if (bytes > lim->maxStorageBufferRange)
            die("pass %s binds %llu bytes of weights, beyond the device's %u", jstr(f.steps[i].pass, "name"),
                (unsigned long long)bytes, lim->maxStorageBufferRange);
        f.steps[i].weights_offset = off;
        repack |= salign > 1 && off % salign != 0;
    }
    VkDeviceSize packed_bytes = w_bytes;
    char *packed = weights;
    if (repack) { /* the manifest's range_alignment is below the device's minStorageBufferOffsetAlignment */
        packed_bytes = 0;
        for (int i = 0; i < f.n_steps; i++) {
            const Json *params = jget(f.steps[i].pass, "params");
            if (params) packed_bytes = align_up(packed_bytes, salign) + (VkDeviceSize)jnum(params, "bytes");
        }
        packed = xmalloc(packed_bytes);
        VkDeviceSize at = 0;
        for (int i = 0; i < f.n_steps; i++) {
            const Json *params = jget(f.steps[i].pass, "params");
            if (!params) continue;
            at = align_up(at, salign);
            memcpy(packed + at, weights + f.steps[i].weights_offset, (size_t)jnum(params, "bytes"));
            f.steps[i].weights_offset = at;
            at += (VkDeviceSize)jnum(params, "bytes");
        }
    }
    f.weights = make_buffer(g, packed_bytes, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT, 0);

    /* 3. the uniform buffer: the FrameUniforms block, then each network pass's PassUniforms */
    const VkDeviceSize ualign = lim->minUniformBufferOffsetAlignment;
    size_t ub_bytes;
    unsigned char *block = frame_uniforms(frame, W, H, radius, yfov, &ub_bytes);
    VkDeviceSize ubo_bytes = align_up(ub_bytes, ualign);
    for (int i = 0; i < f.n_steps; i++)
        if (!jget(f.steps[i].pass, "stage") && jget(f.steps[i].pass, "uniform_block")) {
            f.steps[i].pass_ubo_offset = ubo_bytes;
            ubo_bytes = align_up(ubo_bytes + (VkDeviceSize)jnum(jreq(f.steps[i].pass, "uniform_block"), "bytes"), ualign);
        }
    f.ubo = make_buffer(g, ubo_bytes, VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT, 1);
    memset(f.ubo.map, 0, (size_t)ubo_bytes);
    memcpy(f.ubo.map, block, ub_bytes);
    free(block);
    for (int i = 0; i < f.n_steps; i++)
        if (f.steps[i].pass_ubo_offset)
            pass_uniforms(f.steps[i].pass, (unsigned char *)f.ubo.map + f.steps[i].pass_ubo_offset,
                          (size_t)(ubo_bytes - f.steps[i].pass_ubo_offset));

    /* 4. the pipelines (one per SPIR-V file) and a descriptor set per step */
    uint32_t counts[VK_DESCRIPTOR_TYPE_INPUT_ATTACHMENT + 1] = {0}; /* by VkDescriptorType */
    for (int i = 0; i < f.n_steps; i++) {
        const Json *bindings = jreq(f.steps[i].pass, "bindings");
        for (int k = 0; k < bindings->n; k++) counts[descriptor_type(jstr(bindings->items[k], "kind"))]++;
        if (!f.steps[i].pipe->pipeline) build_pipeline(g, f.steps[i].pipe, f.steps[i].pass, entry, set);
    }
    static const VkDescriptorType kinds[4] = {VK_DESCRIPTOR_TYPE_SAMPLED_IMAGE, VK_DESCRIPTOR_TYPE_STORAGE_IMAGE,
                                              VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER};
    VkDescriptorPoolSize sizes[4];
    uint32_t n_sizes = 0;
    for (int k = 0; k < 4; k++)
        if (counts[kinds[k]]) sizes[n_sizes++] = (VkDescriptorPoolSize){kinds[k], counts[kinds[k]]};
    const VkDescriptorPoolCreateInfo dp = {.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO,
                                           .maxSets = (uint32_t)(f.n_steps ? f.n_steps : 1),
                                           .poolSizeCount = n_sizes, .pPoolSizes = sizes};
    VK(vkCreateDescriptorPool(g->dev, &dp, NULL, &f.dpool));
    for (int i = 0; i < f.n_steps; i++) {
        Step *s = &f.steps[i];
        const char *name = jstr(s->pass, "name");
        const VkDescriptorSetAllocateInfo ai = {.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO,
                                                .descriptorPool = f.dpool, .descriptorSetCount = 1,
                                                .pSetLayouts = &s->pipe->dsl};
        VK(vkAllocateDescriptorSets(g->dev, &ai, &s->set));
        const Json *bindings = jreq(s->pass, "bindings");
        const int nb = bindings->n;
        VkWriteDescriptorSet *writes = xmalloc(sizeof *writes * (size_t)(nb ? nb : 1));
        VkDescriptorImageInfo *images = xmalloc(sizeof *images * (size_t)(nb ? nb : 1));
        VkDescriptorBufferInfo *buffers = xmalloc(sizeof *buffers * (size_t)(nb ? nb : 1));
        for (int k = 0; k < nb; k++) {
            const Json *b = bindings->items[k];
            const VkDescriptorType type = descriptor_type(jstr(b, "kind"));
            writes[k] = (VkWriteDescriptorSet){.sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET, .dstSet = s->set,
                                               .dstBinding = (uint32_t)jnum(b, "binding"), .descriptorCount = 1,
                                               .descriptorType = type};
            if (type == VK_DESCRIPTOR_TYPE_SAMPLED_IMAGE || type == VK_DESCRIPTOR_TYPE_STORAGE_IMAGE) {
                images[k] = (VkDescriptorImageInfo){VK_NULL_HANDLE, find_texture(f.tex, f.n_tex, jstr(b, "resource"))->view,
                                                    VK_IMAGE_LAYOUT_GENERAL};
                writes[k].pImageInfo = &images[k];
            } else if (type == VK_DESCRIPTOR_TYPE_STORAGE_BUFFER) {
                const Json *params = jget(s->pass, "params");
                if (!params || (int)jnum(params, "binding") != (int)writes[k].dstBinding)
                    die("pass %s: storage buffer binding %u is not its weights' range", name, writes[k].dstBinding);
                buffers[k] = (VkDescriptorBufferInfo){f.weights.buf, s->weights_offset, (VkDeviceSize)jnum(params, "bytes")};
                writes[k].pBufferInfo = &buffers[k];
            } else if (!strcmp(jstr(b, "resource"), "FrameUniforms")) {
                buffers[k] = (VkDescriptorBufferInfo){f.ubo.buf, 0, ub_bytes};
                writes[k].pBufferInfo = &buffers[k];
            } else {
                if (!s->pass_ubo_offset) die("pass %s: uniform buffer %s is no block of the frame's", name, jstr(b, "resource"));
                buffers[k] = (VkDescriptorBufferInfo){f.ubo.buf, s->pass_ubo_offset,
                                                      (VkDeviceSize)jnum(jreq(s->pass, "uniform_block"), "bytes")};
                writes[k].pBufferInfo = &buffers[k];
            }
        }
        vkUpdateDescriptorSets(g->dev, (uint32_t)nb, writes, 0, NULL);
        free(writes), free(images), free(buffers);
    }

    /* 2. + 4. + 5. one submission: the images to GENERAL, the weights and the engine's inputs copied in,
     * every step dispatched, the output copied out */
    const size_t px = (size_t)W * H;
    const char *input_ids[2] = {"depth", "normal"};
    Texture *inputs[2];
    VkDeviceSize input_at[2], staged = align_up(packed_bytes, 16);
    for (int k = 0; k < 2; k++) {
        inputs[k] = find_texture(f.tex, f.n_tex, input_ids[k]);
        if (inputs[k]->w != W || inputs[k]->h != H)
            die("input texture %s is %dx%d, the frame %dx%d", inputs[k]->id, inputs[k]->w, inputs[k]->h, W, H);
        input_at[k] = staged;
        staged = align_up(staged + texel_bytes(inputs[k]) * px, 16);
    }
    Texture *res = find_texture(f.tex, f.n_tex, output);
    if (res->w != W || res->h != H) die("output texture %s is %dx%d, the frame %dx%d", res->id, res->w, res->h, W, H);
    Buffer upload = make_buffer(g, staged, VK_BUFFER_USAGE_TRANSFER_SRC_BIT, 1);
    Buffer readback = make_buffer(g, texel_bytes(res) * px, VK_BUFFER_USAGE_TRANSFER_DST_BIT, 1);
    memcpy(upload.map, packed, (size_t)packed_bytes);
    if (packed != weights) free(packed);
    free(weights);
    for (int k = 0; k < 2; k++) {
        float *data = input_texels(gb, px, k, inputs[k]->lanes);
        unsigned char *dst = (unsigned char *)upload.map + input_at[k];
        store_channels(inputs[k]->channel, data, px * (size_t)inputs[k]->lanes, dst);
        free(data);
    }
    VkCommandBuffer cmd = begin_commands(g);
    VkImageMemoryBarrier *to_general = xmalloc(sizeof *to_general * (size_t)(f.n_tex ? f.n_tex : 1));
    for (int i = 0; i < f.n_tex; i++)
        to_general[i] = (VkImageMemoryBarrier){
            .sType = VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER, .srcAccessMask = 0,
            .dstAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT | VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT,
            .oldLayout = VK_IMAGE_LAYOUT_UNDEFINED, .newLayout = VK_IMAGE_LAYOUT_GENERAL,
            .srcQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED, .dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED,
            .image = f.tex[i].image, .subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, (uint32_t)f.tex[i].layers}};
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT,
                         VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 0, 0, NULL, 0, NULL,
                         (uint32_t)f.n_tex, to_general);
    free(to_general);
    const VkBufferCopy wcopy = {0, 0, packed_bytes ? packed_bytes : 16};
    vkCmdCopyBuffer(cmd, upload.buf, f.weights.buf, 1, &wcopy);
    for (int k = 0; k < 2; k++) {
        const VkBufferImageCopy region = {.bufferOffset = input_at[k],
                                          .imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1},
                                          .imageExtent = {(uint32_t)W, (uint32_t)H, 1}};
        vkCmdCopyBufferToImage(cmd, upload.buf, inputs[k]->image, VK_IMAGE_LAYOUT_GENERAL, 1, &region);
    }
    compute_barrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                    VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT);
    record_steps(&f, cmd, -1);
    compute_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                    VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_READ_BIT);
    const VkBufferImageCopy out_region = {.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1},
                                          .imageExtent = {(uint32_t)W, (uint32_t)H, 1}};
    vkCmdCopyImageToBuffer(cmd, res->image, VK_IMAGE_LAYOUT_GENERAL, readback.buf, 1, &out_region);
    compute_barrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT, VK_PIPELINE_STAGE_HOST_BIT,
                    VK_ACCESS_HOST_READ_BIT);
    VK(vkEndCommandBuffer(cmd));
    submit_and_wait(g, cmd);
    vkFreeCommandBuffers(g->dev, g->pool, 1, &cmd);

    /* 5. the AO, lane 0 of the output texture */
    float *ao = xmalloc(sizeof(float) * px);
    const size_t lanes = (size_t)res->lanes;
    for (size_t i = 0; i < px; i++) ao[i] = load_channel(res->channel, readback.map, i * lanes);

    /* the timed runs */
    if (repeats > 0 && g->timestamp_bits > 0 && g->props.limits.timestampPeriod > 0) {
        const VkQueryPoolCreateInfo qp = {.sType = VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO,
                                          .queryType = VK_QUERY_TYPE_TIMESTAMP, .queryCount = 2};
        VK(vkCreateQueryPool(g->dev, &qp, NULL, &f.queries));
    }
    time_steps(&f, -1, repeats, &timing[0], &timing[3]);
    time_steps(&f, STEP_GTAO, repeats, &timing[2], &timing[5]);
    time_steps(&f, STEP_NETWORK, repeats, &timing[1], &timing[4]);
    *n_passes = f.n_steps;

    VK(vkDeviceWaitIdle(g->dev));
    if (f.queries) vkDestroyQueryPool(g->dev, f.queries, NULL);
    Buffer *bufs[4] = {&upload, &readback, &f.weights, &f.ubo};
    for (int i = 0; i < 4; i++) vkDestroyBuffer(g->dev, bufs[i]->buf, NULL), vkFreeMemory(g->dev, bufs[i]->mem, NULL);
    vkDestroyDescriptorPool(g->dev, f.dpool, NULL);
    for (int i = 0; i < f.n_pipes; i++) {
        vkDestroyPipeline(g->dev, f.pipes[i].pipeline, NULL);
        vkDestroyPipelineLayout(g->dev, f.pipes[i].layout, NULL);
        vkDestroyDescriptorSetLayout(g->dev, f.pipes[i].dsl, NULL);
        free(f.pipes[i].words);
    }
    for (int i = 0; i < f.n_tex; i++) {
        vkDestroyImageView(g->dev, f.tex[i].view, NULL);
        vkDestroyImage(g->dev, f.tex[i].image, NULL);
        vkFreeMemory(g->dev, f.tex[i].mem, NULL);
    }
    vkDestroyFence(g->dev, g->fence, NULL);
    vkDestroyCommandPool(g->dev, g->pool, NULL);
    vkDestroyDevice(g->dev, NULL);
    vkDestroyInstance(g->instance, NULL);
    free(f.steps), free(f.pipes), free(f.tex);
    return ao;
}

/* ------------------------------------------------------------------ main */

/* s as a JSON string (quoted, escaped). */
static void json_string(FILE *out, const char *s) {
    fputc('"', out);
    for (; *s; s++) {
        const unsigned char c = (unsigned char)*s;
        if (c == '"' || c == '\\') fputc('\\', out), fputc(c, out);
        else if (c < 0x20) fprintf(out, "\\u%04x", c);
        else fputc(c, out);
    }
    fputc('"', out);
}

int main(int argc, char **argv) {
    const HostArgs args = parse_args(argc, argv);
    const int W = args.W, H = args.H;

    /* the export: vulkan/manifest.json under EXPORT_DIR, or EXPORT_DIR/manifest.json */
    char dir[4096], path[4200];
    snprintf(dir, sizeof dir, "%s/vulkan", args.export_dir);
    snprintf(path, sizeof path, "%s/manifest.json", dir);
    if (!file_exists(path)) snprintf(dir, sizeof dir, "%s", args.export_dir);
    snprintf(path, sizeof path, "%s/manifest.json", dir);
    Json *m = read_json(path);
    if (strcmp(jstr(m, "format"), "neuralao-vulkan-compute")) die("%s is not a Vulkan compute export", path);
    if (!jget(m, "frame")) die("%s has no frame section: this runner runs an export's whole frame (frame.steps)", path);
    if (getenv("NEURALAO_HOST_SSAO_OUT")) die("NEURALAO_HOST_SSAO_OUT is set, but the SSAO baseline runs in the GL host only");

    const int repeats = host_repeats();
    float *gb = load_gbuffer(args.gbuffer, W, H);
    double timing[6] = {-1, -1, -1, -1, -1, -1}; /* frame, network, gtao ms; the same on the wall clock */
    char renderer[256], version[600];
    int n_passes = 0;
    float *ao = run_frame(m, dir, gb, W, H, args.radius, args.yfov, repeats, timing, &n_passes, renderer,
                          sizeof renderer, version, sizeof version);

    write_ao(args.out, ao, W, H);
    fprintf(stderr, HOST_NAME ": %dx%d (frame, %s), %d passes -> %s\n", W, H, renderer, n_passes, args.out);
    if (repeats > 0) {
        fputs("{\"renderer\": ", stdout);
        json_string(stdout, renderer);
        fputs(", \"api\": \"vulkan\", \"version\": ", stdout);
        json_string(stdout, version);
        printf(", \"width\": %d, \"height\": %d, \"repeats\": %d, \"path\": \"frame\", \"frame_ms\": %.4f, "
               "\"network_ms\": %.4f, \"gtao_ms\": %.4f, \"ssao_ms\": -1.0000, \"frame_wall_ms\": %.4f, "
               "\"network_wall_ms\": %.4f, \"gtao_wall_ms\": %.4f, \"ssao_wall_ms\": -1.0000, \"passes\": %d}\n",
               W, H, repeats, timing[0], timing[1], timing[2], timing[3], timing[4], timing[5], n_passes);
    }
    free(ao), free(gb);
    return 0;
}
