/* Minimal Vulkan compute host for the conformance harness (caustics_jax/conformance.py).
 *
 *   cj_vk_host SHADER.spv IN.bin OUT.bin COUNT STRIDE [EXTRA.bin ...]
 *
 * Runs the compute shader once over COUNT records: binding 0 is a storage buffer holding
 * IN.bin (the exported std430 records), binding 1 a storage buffer of COUNT * STRIDE
 * bytes the shader writes its records into, push constant 0 the record count, and each
 * EXTRA.bin a read-only storage buffer at binding 2, 3, ... (a scene's parameters,
 * vertices and faces). Writes binding 1 to OUT.bin; prints the device name and then
 * "dispatch_seconds MIN MEDIAN" (wall time of submit + wait, CJ_VK_REPEAT=n dispatches,
 * default 1) to stdout. Exit status 3 means "no Vulkan device" (the harness skips), any
 * other non-zero status an error.
 *
 *   cj_vk_host --list
 *
 * prints one line per Vulkan device: index, type (integrated, discrete, virtual, cpu,
 * other), vendor and device IDs, driver version, API version, subgroup size (0 when the
 * device is Vulkan 1.0) and name, tab-separated. CJ_VK_DEVICE=<index> picks a device by
 * index, CJ_VK_DEVICE_NAME=<text> the first whose name contains the text; the default is the
 * first device with a compute queue. A run prints the device's name first, then
 * "device_type", "driver_version" and the timings.
 *
 * Host-visible, host-coherent memory only: on lavapipe all memory is, and for a test
 * harness the staging copy of a discrete GPU is not worth its code.
 */
#define _POSIX_C_SOURCE 199309L /* clock_gettime under -std=c11 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <vulkan/vulkan.h>

#define LOCAL_SIZE 64u
#define MAX_BUFFERS 8
#define MAX_REPEAT 64

static int fail(const char *what, VkResult r) {
    fprintf(stderr, "cj_vk_host: %s failed (VkResult %d)\n", what, (int)r);
    return 1;
}

#define CHECK(call, what)                   \
    do {                                    \
        VkResult r_ = (call);               \
        if (r_ != VK_SUCCESS) return fail(what, r_); \
    } while (0)

static void *read_file(const char *path, size_t *size) {
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    void *buf = malloc(n > 0 ? (size_t)n : 1);
    if (buf && n > 0 && fread(buf, 1, (size_t)n, f) != (size_t)n) {
        free(buf);
        buf = NULL;
    }
    fclose(f);
    *size = (size_t)n;
    return buf;
}

static int find_memory(VkPhysicalDevice phys, uint32_t type_bits, uint32_t *index) {
    VkPhysicalDeviceMemoryProperties props;
    vkGetPhysicalDeviceMemoryProperties(phys, &props);
    VkMemoryPropertyFlags want = VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
    for (uint32_t i = 0; i < props.memoryTypeCount; ++i) {
        if ((type_bits & (1u << i)) && (props.memoryTypes[i].propertyFlags & want) == want) {
            *index = i;
            return 1;
        }
    }
    return 0;
}

static int make_buffer(VkPhysicalDevice phys, VkDevice dev, VkDeviceSize size, VkBuffer *buf, VkDeviceMemory *mem) {
    VkBufferCreateInfo bi = {VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
    bi.size = size;
    bi.usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT;
    bi.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
    CHECK(vkCreateBuffer(dev, &bi, NULL, buf), "vkCreateBuffer");
    VkMemoryRequirements req;
    vkGetBufferMemoryRequirements(dev, *buf, &req);
    VkMemoryAllocateInfo ai = {VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
    ai.allocationSize = req.size;
    if (!find_memory(phys, req.memoryTypeBits, &ai.memoryTypeIndex)) {
        fprintf(stderr, "cj_vk_host: no host-visible coherent memory type\n");
        return 1;
    }
    CHECK(vkAllocateMemory(dev, &ai, NULL, mem), "vkAllocateMemory");
    CHECK(vkBindBufferMemory(dev, *buf, *mem, 0), "vkBindBufferMemory");
    return 0;
}

static const char *type_name(VkPhysicalDeviceType t) {
    switch (t) {
    case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU: return "integrated";
    case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU: return "discrete";
    case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU: return "virtual";
    case VK_PHYSICAL_DEVICE_TYPE_CPU: return "cpu";
    default: return "other";
    }
}

/* A Vulkan instance at API version `api` (0 on success). */
static int open_instance(uint32_t api, const char *name, VkInstance *inst) {
    VkApplicationInfo app = {VK_STRUCTURE_TYPE_APPLICATION_INFO};
    app.pApplicationName = name;
    app.apiVersion = api;
    VkInstanceCreateInfo ici = {VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO};
    ici.pApplicationInfo = &app;
    return vkCreateInstance(&ici, NULL, inst) == VK_SUCCESS ? 0 : 1;
}

/* The instance's physical devices, at most 16. */
static uint32_t physical_devices(VkInstance inst, VkPhysicalDevice physs[16]) {
    uint32_t n_phys = 0;
    vkEnumeratePhysicalDevices(inst, &n_phys, NULL);
    if (n_phys > 16) n_phys = 16;
    if (n_phys) vkEnumeratePhysicalDevices(inst, &n_phys, physs);
    return n_phys;
}

/* --list: the devices, one line each (see the header). Exit status 3 without any. */
static int list_devices(void) {
    VkInstance inst;
    uint32_t api = VK_API_VERSION_1_1;
    if (open_instance(api, "caustics_jax device list", &inst)) {
        api = VK_API_VERSION_1_0; /* a 1.0 loader: no subgroup query */
        if (open_instance(api, "caustics_jax device list", &inst)) {
            fprintf(stderr, "cj_vk_host: no Vulkan instance (no loader or no driver)\n");
            return 3;
        }
    }
    VkPhysicalDevice physs[16];
    uint32_t n_phys = physical_devices(inst, physs);
    for (uint32_t d = 0; d < n_phys; ++d) {
        VkPhysicalDeviceProperties props;
        vkGetPhysicalDeviceProperties(physs[d], &props);
        uint32_t subgroup = 0;
        if (api >= VK_API_VERSION_1_1 && props.apiVersion >= VK_API_VERSION_1_1) {
            VkPhysicalDeviceSubgroupProperties sub = {VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SUBGROUP_PROPERTIES};
            VkPhysicalDeviceProperties2 p2 = {VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2};
            p2.pNext = &sub;
            vkGetPhysicalDeviceProperties2(physs[d], &p2);
            subgroup = sub.subgroupSize;
        }
        printf("%u\t%s\t0x%04x\t0x%04x\t%u\t%u.%u.%u\t%u\t%s\n", d, type_name(props.deviceType), props.vendorID,
               props.deviceID, props.driverVersion, VK_VERSION_MAJOR(props.apiVersion),
               VK_VERSION_MINOR(props.apiVersion), VK_VERSION_PATCH(props.apiVersion), subgroup, props.deviceName);
    }
    vkDestroyInstance(inst, NULL);
    return n_phys ? 0 : 3;
}

int main(int argc, char **argv) {
    if (argc == 2 && strcmp(argv[1], "--list") == 0) return list_devices();
    if (argc < 6 || argc > 6 + MAX_BUFFERS - 2) {
        fprintf(stderr, "usage: %s SHADER.spv IN.bin OUT.bin COUNT STRIDE [EXTRA.bin ...] (at most %d extra)\n",
                argv[0], MAX_BUFFERS - 2);
        return 2;
    }
    int n_bufs = argc - 4; /* in, out, extras */
    void *extra[MAX_BUFFERS];
    size_t extra_size[MAX_BUFFERS];
    for (int i = 2; i < n_bufs; ++i) {
        extra[i] = read_file(argv[4 + i], &extra_size[i]);
        if (!extra[i]) {
            fprintf(stderr, "cj_vk_host: cannot read %s\n", argv[4 + i]);
            return 2;
        }
    }
    int repeat = getenv("CJ_VK_REPEAT") ? atoi(getenv("CJ_VK_REPEAT")) : 1;
    if (repeat < 1) repeat = 1;
    if (repeat > MAX_REPEAT) repeat = MAX_REPEAT;
    uint32_t count = (uint32_t)strtoul(argv[4], NULL, 10);
    VkDeviceSize stride = (VkDeviceSize)strtoull(argv[5], NULL, 10);
    size_t spv_size = 0, in_size = 0;
    uint32_t *spv = read_file(argv[1], &spv_size);
    void *in = read_file(argv[2], &in_size);
    if (!spv || !in || spv_size % 4 != 0) {
        fprintf(stderr, "cj_vk_host: cannot read %s or %s\n", argv[1], argv[2]);
        return 2;
    }
    VkDeviceSize out_size = (VkDeviceSize)count * stride;
    if (count == 0 || stride == 0 || in_size != out_size) {
        fprintf(stderr, "cj_vk_host: %s holds %zu bytes, expected COUNT * STRIDE = %llu\n", argv[2], in_size,
                (unsigned long long)out_size);
        return 2;
    }

    VkInstance inst;
    if (open_instance(VK_API_VERSION_1_0, "caustics_jax conformance", &inst)) {
        fprintf(stderr, "cj_vk_host: no Vulkan instance (no loader or no driver)\n");
        return 3;
    }
    VkPhysicalDevice physs[16];
    uint32_t n_phys = physical_devices(inst, physs);
    if (n_phys == 0) {
        fprintf(stderr, "cj_vk_host: no Vulkan physical device\n");
        return 3;
    }

    /* First device with a compute queue; CJ_VK_DEVICE=<index> or CJ_VK_DEVICE_NAME=<text>
       picks another. */
    const char *want = getenv("CJ_VK_DEVICE");
    const char *want_name = getenv("CJ_VK_DEVICE_NAME");
    if (want && !*want) want = NULL;
    if (want_name && !*want_name) want_name = NULL;
    VkPhysicalDevice phys = VK_NULL_HANDLE;
    uint32_t family = 0;
    for (uint32_t d = 0; d < n_phys && phys == VK_NULL_HANDLE; ++d) {
        if (want && (uint32_t)atoi(want) != d) continue;
        if (want_name) {
            VkPhysicalDeviceProperties named;
            vkGetPhysicalDeviceProperties(physs[d], &named);
            if (!strstr(named.deviceName, want_name)) continue;
        }
        uint32_t n_fam = 0;
        vkGetPhysicalDeviceQueueFamilyProperties(physs[d], &n_fam, NULL);
        VkQueueFamilyProperties fams[32];
        if (n_fam > 32) n_fam = 32;
        vkGetPhysicalDeviceQueueFamilyProperties(physs[d], &n_fam, fams);
        for (uint32_t f = 0; f < n_fam; ++f) {
            if (fams[f].queueFlags & VK_QUEUE_COMPUTE_BIT) {
                phys = physs[d];
                family = f;
                break;
            }
        }
    }
    if (phys == VK_NULL_HANDLE) {
        fprintf(stderr, "cj_vk_host: no Vulkan device with a compute queue\n");
        return 3;
    }
    VkPhysicalDeviceProperties props;
    vkGetPhysicalDeviceProperties(phys, &props);

    float prio = 1.0f;
    VkDeviceQueueCreateInfo qci = {VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO};
    qci.queueFamilyIndex = family;
    qci.queueCount = 1;
    qci.pQueuePriorities = &prio;
    VkDeviceCreateInfo dci = {VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO};
    dci.queueCreateInfoCount = 1;
    dci.pQueueCreateInfos = &qci;
    VkDevice dev;
    CHECK(vkCreateDevice(phys, &dci, NULL, &dev), "vkCreateDevice");
    VkQueue queue;
    vkGetDeviceQueue(dev, family, 0, &queue);

    VkBuffer bufs[MAX_BUFFERS];
    VkDeviceMemory mems[MAX_BUFFERS];
    for (int i = 0; i < n_bufs; ++i) {
        VkDeviceSize size = i < 2 ? out_size : (extra_size[i] > 0 ? (VkDeviceSize)extra_size[i] : 4);
        if (make_buffer(phys, dev, size, &bufs[i], &mems[i])) return 1;
    }
    void *ptr;
    CHECK(vkMapMemory(dev, mems[0], 0, out_size, 0, &ptr), "vkMapMemory");
    memcpy(ptr, in, in_size);
    vkUnmapMemory(dev, mems[0]);
    CHECK(vkMapMemory(dev, mems[1], 0, out_size, 0, &ptr), "vkMapMemory");
    memset(ptr, 0xFF, out_size); /* NaN everywhere: a field the shader forgets cannot pass */
    vkUnmapMemory(dev, mems[1]);
    for (int i = 2; i < n_bufs; ++i) {
        if (extra_size[i] == 0) continue;
        CHECK(vkMapMemory(dev, mems[i], 0, extra_size[i], 0, &ptr), "vkMapMemory");
        memcpy(ptr, extra[i], extra_size[i]);
        vkUnmapMemory(dev, mems[i]);
    }

    VkShaderModuleCreateInfo smi = {VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO};
    smi.codeSize = spv_size;
    smi.pCode = spv;
    VkShaderModule module;
    CHECK(vkCreateShaderModule(dev, &smi, NULL, &module), "vkCreateShaderModule");

    VkDescriptorSetLayoutBinding binds[MAX_BUFFERS];
    for (int i = 0; i < n_bufs; ++i) {
        VkDescriptorSetLayoutBinding b = {(uint32_t)i, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1,
                                          VK_SHADER_STAGE_COMPUTE_BIT, NULL};
        binds[i] = b;
    }
    VkDescriptorSetLayoutCreateInfo dli = {VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO};
    dli.bindingCount = (uint32_t)n_bufs;
    dli.pBindings = binds;
    VkDescriptorSetLayout dsl;
    CHECK(vkCreateDescriptorSetLayout(dev, &dli, NULL, &dsl), "vkCreateDescriptorSetLayout");
    VkPushConstantRange pcr = {VK_SHADER_STAGE_COMPUTE_BIT, 0, 4};
    VkPipelineLayoutCreateInfo pli = {VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO};
    pli.setLayoutCount = 1;
    pli.pSetLayouts = &dsl;
    pli.pushConstantRangeCount = 1;
    pli.pPushConstantRanges = &pcr;
    VkPipelineLayout layout;
    CHECK(vkCreatePipelineLayout(dev, &pli, NULL, &layout), "vkCreatePipelineLayout");
    VkComputePipelineCreateInfo cpi = {VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO};
    cpi.stage.sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
    cpi.stage.stage = VK_SHADER_STAGE_COMPUTE_BIT;
    cpi.stage.module = module;
    cpi.stage.pName = "main";
    cpi.layout = layout;
    VkPipeline pipeline;
    CHECK(vkCreateComputePipelines(dev, VK_NULL_HANDLE, 1, &cpi, NULL, &pipeline), "vkCreateComputePipelines");

    VkDescriptorPoolSize ps = {VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, (uint32_t)n_bufs};
    VkDescriptorPoolCreateInfo dpi = {VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO};
    dpi.maxSets = 1;
    dpi.poolSizeCount = 1;
    dpi.pPoolSizes = &ps;
    VkDescriptorPool pool;
    CHECK(vkCreateDescriptorPool(dev, &dpi, NULL, &pool), "vkCreateDescriptorPool");
    VkDescriptorSetAllocateInfo dsai = {VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO};
    dsai.descriptorPool = pool;
    dsai.descriptorSetCount = 1;
    dsai.pSetLayouts = &dsl;
    VkDescriptorSet set;
    CHECK(vkAllocateDescriptorSets(dev, &dsai, &set), "vkAllocateDescriptorSets");
    VkDescriptorBufferInfo dbi[MAX_BUFFERS];
    VkWriteDescriptorSet w[MAX_BUFFERS];
    for (int i = 0; i < n_bufs; ++i) {
        dbi[i].buffer = bufs[i];
        dbi[i].offset = 0;
        dbi[i].range = VK_WHOLE_SIZE;
        memset(&w[i], 0, sizeof w[i]);
        w[i].sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
        w[i].dstSet = set;
        w[i].dstBinding = (uint32_t)i;
        w[i].descriptorCount = 1;
        w[i].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
        w[i].pBufferInfo = &dbi[i];
    }
    vkUpdateDescriptorSets(dev, (uint32_t)n_bufs, w, 0, NULL);

    VkCommandPoolCreateInfo cpci = {VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
    cpci.queueFamilyIndex = family;
    VkCommandPool cmd_pool;
    CHECK(vkCreateCommandPool(dev, &cpci, NULL, &cmd_pool), "vkCreateCommandPool");
    VkCommandBufferAllocateInfo cbai = {VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
    cbai.commandPool = cmd_pool;
    cbai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
    cbai.commandBufferCount = 1;
    VkCommandBuffer cmd;
    CHECK(vkAllocateCommandBuffers(dev, &cbai, &cmd), "vkAllocateCommandBuffers");
    VkCommandBufferBeginInfo cbbi = {VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
    cbbi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    CHECK(vkBeginCommandBuffer(cmd, &cbbi), "vkBeginCommandBuffer");
    vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline);
    vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, layout, 0, 1, &set, 0, NULL);
    vkCmdPushConstants(cmd, layout, VK_SHADER_STAGE_COMPUTE_BIT, 0, 4, &count);
    vkCmdDispatch(cmd, (count + LOCAL_SIZE - 1) / LOCAL_SIZE, 1, 1);
    VkMemoryBarrier barrier = {VK_STRUCTURE_TYPE_MEMORY_BARRIER};
    barrier.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT;
    barrier.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &barrier, 0,
                         NULL, 0, NULL);
    CHECK(vkEndCommandBuffer(cmd), "vkEndCommandBuffer");
    VkSubmitInfo si = {VK_STRUCTURE_TYPE_SUBMIT_INFO};
    si.commandBufferCount = 1;
    si.pCommandBuffers = &cmd;
    VkFenceCreateInfo fci = {VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
    VkFence fence;
    CHECK(vkCreateFence(dev, &fci, NULL, &fence), "vkCreateFence");
    /* Wall time of submit to fence, and the process's CPU time over it (all threads: a CPU
     * driver such as lavapipe runs the shader in this process), per dispatch. */
    double seconds[MAX_REPEAT], cpu[MAX_REPEAT];
    for (int r = 0; r < repeat; ++r) {
        struct timespec t0, t1, c0, c1;
        clock_gettime(CLOCK_MONOTONIC, &t0);
        clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c0);
        CHECK(vkQueueSubmit(queue, 1, &si, fence), "vkQueueSubmit");
        CHECK(vkWaitForFences(dev, 1, &fence, VK_TRUE, 600ull * 1000000000ull), "vkWaitForFences");
        clock_gettime(CLOCK_MONOTONIC, &t1);
        clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c1);
        seconds[r] = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
        cpu[r] = (double)(c1.tv_sec - c0.tv_sec) + 1e-9 * (double)(c1.tv_nsec - c0.tv_nsec);
        CHECK(vkResetFences(dev, 1, &fence), "vkResetFences");
    }
    for (int a = 1; a < repeat; ++a) /* insertion sorts: min and median */
        for (int b = a; b > 0 && seconds[b] < seconds[b - 1]; --b) {
            double tmp = seconds[b];
            seconds[b] = seconds[b - 1];
            seconds[b - 1] = tmp;
        }
    for (int a = 1; a < repeat; ++a)
        for (int b = a; b > 0 && cpu[b] < cpu[b - 1]; --b) {
            double tmp = cpu[b];
            cpu[b] = cpu[b - 1];
            cpu[b - 1] = tmp;
        }

    CHECK(vkMapMemory(dev, mems[1], 0, out_size, 0, &ptr), "vkMapMemory");
    FILE *out = fopen(argv[3], "wb");
    if (!out || fwrite(ptr, 1, out_size, out) != out_size) {
        fprintf(stderr, "cj_vk_host: cannot write %s\n", argv[3]);
        return 1;
    }
    fclose(out);
    vkUnmapMemory(dev, mems[1]);
    printf("%s\ndevice_type %s\ndriver_version %u\ndispatch_seconds %.9f %.9f\ndispatch_cpu_seconds %.9f %.9f\n",
           props.deviceName, type_name(props.deviceType), props.driverVersion, seconds[0], seconds[repeat / 2], cpu[0],
           cpu[repeat / 2]);

    vkDestroyFence(dev, fence, NULL);
    vkDestroyCommandPool(dev, cmd_pool, NULL);
    vkDestroyDescriptorPool(dev, pool, NULL);
    vkDestroyPipeline(dev, pipeline, NULL);
    vkDestroyPipelineLayout(dev, layout, NULL);
    vkDestroyDescriptorSetLayout(dev, dsl, NULL);
    vkDestroyShaderModule(dev, module, NULL);
    for (int i = 0; i < n_bufs; ++i) {
        vkDestroyBuffer(dev, bufs[i], NULL);
        vkFreeMemory(dev, mems[i], NULL);
    }
    for (int i = 2; i < n_bufs; ++i) free(extra[i]);
    vkDestroyDevice(dev, NULL);
    vkDestroyInstance(inst, NULL);
    free(spv);
    free(in);
    return 0;
}
