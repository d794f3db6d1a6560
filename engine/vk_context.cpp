#include "isotouch/engine/vk_context.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sstream>

namespace isotouch::engine {

const char* vk_result_name(VkResult r) {
  switch (r) {
#define CASE(x) case x: return #x;
    CASE(VK_SUCCESS) CASE(VK_NOT_READY) CASE(VK_TIMEOUT) CASE(VK_INCOMPLETE)
    CASE(VK_ERROR_OUT_OF_HOST_MEMORY) CASE(VK_ERROR_OUT_OF_DEVICE_MEMORY)
    CASE(VK_ERROR_INITIALIZATION_FAILED) CASE(VK_ERROR_DEVICE_LOST)
    CASE(VK_ERROR_MEMORY_MAP_FAILED) CASE(VK_ERROR_LAYER_NOT_PRESENT)
    CASE(VK_ERROR_EXTENSION_NOT_PRESENT) CASE(VK_ERROR_FEATURE_NOT_PRESENT)
    CASE(VK_ERROR_INCOMPATIBLE_DRIVER) CASE(VK_ERROR_TOO_MANY_OBJECTS)
    CASE(VK_ERROR_FORMAT_NOT_SUPPORTED) CASE(VK_ERROR_FRAGMENTED_POOL)
    CASE(VK_ERROR_OUT_OF_POOL_MEMORY)
#undef CASE
    default: return "VK_ERROR_(unknown)";
  }
}

void vk_check_failed(const char* call, VkResult r, const char* file, int line) {
  std::ostringstream s;
  s << file << ":" << line << ": " << call << " returned " << vk_result_name(r) << " ("
    << int(r) << ")";
  std::fprintf(stderr, "isotouch: Vulkan error: %s\n", s.str().c_str());
  throw VulkanError(s.str());
}

namespace {

std::string lower(std::string s) {
  for (auto& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

const char* type_name(VkPhysicalDeviceType t) {
  switch (t) {
    case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU: return "discrete-gpu";
    case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU: return "integrated-gpu";
    case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU: return "virtual-gpu";
    case VK_PHYSICAL_DEVICE_TYPE_CPU: return "cpu";
    default: return "other";
  }
}

int type_rank(VkPhysicalDeviceType t) {
  switch (t) {
    case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU: return 0;
    case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU: return 1;
    case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU: return 2;
    case VK_PHYSICAL_DEVICE_TYPE_CPU: return 3;
    default: return 4;
  }
}

const char kValidationLayer[] = "VK_LAYER_KHRONOS_validation";

bool layer_available(const char* name) {
  std::uint32_t n = 0;
  vkEnumerateInstanceLayerProperties(&n, nullptr);
  std::vector<VkLayerProperties> layers(n);
  vkEnumerateInstanceLayerProperties(&n, layers.data());
  return std::any_of(layers.begin(), layers.end(),
                     [&](const VkLayerProperties& l) { return std::strcmp(l.layerName, name) == 0; });
}

bool layer_has_extension(const char* layer, const char* ext) {
  std::uint32_t n = 0;
  vkEnumerateInstanceExtensionProperties(layer, &n, nullptr);
  std::vector<VkExtensionProperties> e(n);
  vkEnumerateInstanceExtensionProperties(layer, &n, e.data());
  return std::any_of(e.begin(), e.end(),
                     [&](const VkExtensionProperties& x) { return std::strcmp(x.extensionName, ext) == 0; });
}

Result<VkInstance> make_instance(bool validation, bool sync_validation = false,
                                 const std::vector<std::string>& extra = {}) {
  VkApplicationInfo app{VK_STRUCTURE_TYPE_APPLICATION_INFO};
  app.pApplicationName = "isotouch";
  app.apiVersion = VK_API_VERSION_1_1;
  VkInstanceCreateInfo ci{VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO};
  ci.pApplicationInfo = &app;
  const char* layers[] = {kValidationLayer};
  const char* exts[] = {VK_EXT_DEBUG_UTILS_EXTENSION_NAME, VK_EXT_VALIDATION_FEATURES_EXTENSION_NAME};
  const VkValidationFeatureEnableEXT sync_feature =
      VK_VALIDATION_FEATURE_ENABLE_SYNCHRONIZATION_VALIDATION_EXT;
  VkValidationFeaturesEXT features{VK_STRUCTURE_TYPE_VALIDATION_FEATURES_EXT};
  features.enabledValidationFeatureCount = 1;
  features.pEnabledValidationFeatures = &sync_feature;
  if (validation) {
    if (!layer_available(kValidationLayer))
      return Result<VkInstance>::fail(
          "validation requested but VK_LAYER_KHRONOS_validation is not installed "
          "(Debian package vulkan-validationlayers)");
    ci.enabledLayerCount = 1;
    ci.ppEnabledLayerNames = layers;
    ci.enabledExtensionCount = 1;
    ci.ppEnabledExtensionNames = exts;
    if (sync_validation &&
        layer_has_extension(kValidationLayer, VK_EXT_VALIDATION_FEATURES_EXTENSION_NAME)) {
      ci.enabledExtensionCount = 2;
      ci.pNext = &features;
    }
  }
  // A window system's extensions come after the validation ones (which stay first).
  std::vector<const char*> all(exts, exts + ci.enabledExtensionCount);
  for (const std::string& e : extra) {
    if (!layer_has_extension(nullptr, e.c_str()))
      return Result<VkInstance>::fail("the Vulkan instance lacks extension " + e +
                                      " (a window needs it; is a Vulkan WSI driver installed?)");
    all.push_back(e.c_str());
  }
  if (!extra.empty()) {
    ci.enabledExtensionCount = std::uint32_t(all.size());
    ci.ppEnabledExtensionNames = all.data();
  }
  VkInstance inst = VK_NULL_HANDLE;
  const VkResult r = vkCreateInstance(&ci, nullptr, &inst);
  if (r != VK_SUCCESS)
    return Result<VkInstance>::fail(std::string("vkCreateInstance failed: ") + vk_result_name(r) +
                                    " (is a Vulkan driver installed? Debian: mesa-vulkan-drivers)");
  return Result<VkInstance>::ok(inst);
}

std::vector<VkPhysicalDevice> physical_devices(VkInstance inst) {
  std::uint32_t n = 0;
  vkEnumeratePhysicalDevices(inst, &n, nullptr);
  std::vector<VkPhysicalDevice> devs(n);
  if (n) vkEnumeratePhysicalDevices(inst, &n, devs.data());
  return devs;
}

DeviceInfo describe(VkPhysicalDevice pd) {
  VkPhysicalDeviceProperties p;
  vkGetPhysicalDeviceProperties(pd, &p);
  DeviceInfo d;
  d.name = p.deviceName;
  d.type = type_name(p.deviceType);
  d.api_version = p.apiVersion;
  std::ostringstream s;
  s << VK_API_VERSION_MAJOR(p.apiVersion) << "." << VK_API_VERSION_MINOR(p.apiVersion) << "."
    << VK_API_VERSION_PATCH(p.apiVersion);
  d.driver = "Vulkan " + s.str();
  return d;
}

}  // namespace

VKAPI_ATTR VkBool32 VKAPI_CALL VulkanContext::on_message(
    VkDebugUtilsMessageSeverityFlagBitsEXT severity, VkDebugUtilsMessageTypeFlagsEXT,
    const VkDebugUtilsMessengerCallbackDataEXT* data, void* user) {
  if (severity >= VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT) {
    static_cast<VulkanContext*>(user)->validation_count_.fetch_add(1);
    std::fprintf(stderr, "isotouch: Vulkan validation: %s\n", data->pMessage);
  }
  return VK_FALSE;
}

Result<std::vector<DeviceInfo>> VulkanContext::list_devices() {
  auto inst = make_instance(false);
  if (!inst) return Result<std::vector<DeviceInfo>>::fail(inst.error);
  std::vector<DeviceInfo> out;
  for (VkPhysicalDevice pd : physical_devices(*inst.value)) out.push_back(describe(pd));
  vkDestroyInstance(*inst.value, nullptr);
  return Result<std::vector<DeviceInfo>>::ok(std::move(out));
}

Result<std::unique_ptr<VulkanContext>> VulkanContext::create(const ContextOptions& opt) {
  using R = Result<std::unique_ptr<VulkanContext>>;
  const char* env_val = std::getenv("ISOTOUCH_VALIDATION");
  const bool validation = opt.validation || (env_val && std::string(env_val) == "1");
  auto inst = make_instance(validation, opt.synchronization_validation, opt.instance_extensions);
  if (!inst) return R::fail(inst.error);
  std::unique_ptr<VulkanContext> ctx(new VulkanContext());
  ctx->instance_ = *inst.value;

  if (validation) {
    auto create_messenger = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(ctx->instance_, "vkCreateDebugUtilsMessengerEXT"));
    if (create_messenger) {
      VkDebugUtilsMessengerCreateInfoEXT mi{VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT};
      mi.messageSeverity = VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT |
                           VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
      mi.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT |
                       VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                       VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT;
      mi.pfnUserCallback = &VulkanContext::on_message;
      mi.pUserData = ctx.get();
      VK_CHECK(create_messenger(ctx->instance_, &mi, nullptr, &ctx->messenger_));
    }
  }

  std::vector<VkPhysicalDevice> devs = physical_devices(ctx->instance_);
  if (devs.empty()) return R::fail("no Vulkan physical device found (Debian: mesa-vulkan-drivers provides lavapipe)");

  std::string want = opt.device;
  if (want.empty())
    if (const char* e = std::getenv("ISOTOUCH_DEVICE")) want = e;

  auto compute_family = [](VkPhysicalDevice pd) -> std::optional<std::uint32_t> {
    std::uint32_t n = 0;
    vkGetPhysicalDeviceQueueFamilyProperties(pd, &n, nullptr);
    std::vector<VkQueueFamilyProperties> q(n);
    vkGetPhysicalDeviceQueueFamilyProperties(pd, &n, q.data());
    for (std::uint32_t i = 0; i < n; ++i)
      if (q[i].queueFlags & VK_QUEUE_COMPUTE_BIT) return i;
    return std::nullopt;
  };

  VkPhysicalDevice chosen = VK_NULL_HANDLE;
  if (!want.empty()) {
    const bool numeric = std::all_of(want.begin(), want.end(), ::isdigit);
    for (std::size_t i = 0; i < devs.size(); ++i) {
      const DeviceInfo d = describe(devs[i]);
      if ((numeric && std::stoul(want) == i) ||
          (!numeric && lower(d.name).find(lower(want)) != std::string::npos)) {
        chosen = devs[i];
        break;
      }
    }
    if (!chosen) {
      std::string names;
      for (std::size_t i = 0; i < devs.size(); ++i)
        names += (i ? ", " : "") + std::to_string(i) + ": " + describe(devs[i]).name;
      return R::fail("no Vulkan device matches '" + want + "' (available: " + names + ")");
    }
  } else {
    int best = 99;
    for (VkPhysicalDevice pd : devs) {
      VkPhysicalDeviceProperties p;
      vkGetPhysicalDeviceProperties(pd, &p);
      if (!compute_family(pd)) continue;
      if (type_rank(p.deviceType) < best) {
        best = type_rank(p.deviceType);
        chosen = pd;
      }
    }
    if (!chosen) return R::fail("no Vulkan device with a compute queue");
  }
  const auto fam = compute_family(chosen);
  if (!fam) return R::fail("Vulkan device '" + describe(chosen).name + "' has no compute queue");
  ctx->phys_ = chosen;
  ctx->family_ = *fam;
  ctx->info_ = describe(chosen);
  vkGetPhysicalDeviceProperties(chosen, &ctx->props_);
  vkGetPhysicalDeviceMemoryProperties(chosen, &ctx->mem_props_);
  {
    const VkMemoryPropertyFlags host = VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
    bool any = false, all = true;
    for (std::uint32_t i = 0; i < ctx->mem_props_.memoryTypeCount; ++i) {
      const VkMemoryPropertyFlags f = ctx->mem_props_.memoryTypes[i].propertyFlags;
      if (!(f & VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT)) continue;
      any = true;
      all = all && (f & host) == host;
    }
    ctx->unified_memory_ = any && all;
  }
  {
    VkPhysicalDeviceMaintenance3Properties m3{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_MAINTENANCE_3_PROPERTIES};
    VkPhysicalDeviceProperties2 p2{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2};
    p2.pNext = &m3;
    vkGetPhysicalDeviceProperties2(chosen, &p2);  // core in Vulkan 1.1, which the instance asks for
    ctx->max_allocation_ = m3.maxMemoryAllocationSize;
  }
  {
    std::uint32_t n = 0;
    vkGetPhysicalDeviceQueueFamilyProperties(chosen, &n, nullptr);
    std::vector<VkQueueFamilyProperties> q(n);
    vkGetPhysicalDeviceQueueFamilyProperties(chosen, &n, q.data());
    ctx->timestamp_bits_ = q[ctx->family_].timestampValidBits;
    if (ctx->props_.limits.timestampPeriod <= 0.f) ctx->timestamp_bits_ = 0;
  }

  const float prio = 1.0f;
  VkDeviceQueueCreateInfo qi{VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO};
  qi.queueFamilyIndex = ctx->family_;
  qi.queueCount = 1;
  qi.pQueuePriorities = &prio;
  VkDeviceCreateInfo di{VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO};
  di.queueCreateInfoCount = 1;
  di.pQueueCreateInfos = &qi;
  std::vector<VkExtensionProperties> offered;
  {
    std::uint32_t n = 0;
    vkEnumerateDeviceExtensionProperties(chosen, nullptr, &n, nullptr);
    offered.resize(n);
    vkEnumerateDeviceExtensionProperties(chosen, nullptr, &n, offered.data());
    offered.resize(n);
  }
  auto has = [&](const char* ext) {
    return std::any_of(offered.begin(), offered.end(),
                       [&](const VkExtensionProperties& x) { return std::strcmp(x.extensionName, ext) == 0; });
  };
  std::vector<const char*> device_exts;
  const char* swapchain_ext = VK_KHR_SWAPCHAIN_EXTENSION_NAME;
  if (opt.swapchain) {
    if (!has(swapchain_ext))
      return R::fail("Vulkan device '" + ctx->info_.name + "' lacks " + swapchain_ext + " (needed to show a window)");
    device_exts.push_back(swapchain_ext);
  }
  // Host memory imported as buffers (no copy of an input the host already holds), where
  // device memory is host memory anyway (unified memory: lavapipe, integrated GPUs).
  if (ctx->unified_memory_ && has(VK_EXT_EXTERNAL_MEMORY_HOST_EXTENSION_NAME)) {
    VkPhysicalDeviceExternalMemoryHostPropertiesEXT h{
        VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_EXTERNAL_MEMORY_HOST_PROPERTIES_EXT};
    VkPhysicalDeviceProperties2 p2{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2};
    p2.pNext = &h;
    vkGetPhysicalDeviceProperties2(chosen, &p2);
    if (h.minImportedHostPointerAlignment > 0) {
      device_exts.push_back(VK_EXT_EXTERNAL_MEMORY_HOST_EXTENSION_NAME);
      ctx->host_import_alignment_ = h.minImportedHostPointerAlignment;
    }
  }
  di.enabledExtensionCount = std::uint32_t(device_exts.size());
  di.ppEnabledExtensionNames = device_exts.empty() ? nullptr : device_exts.data();
  const VkResult r = vkCreateDevice(chosen, &di, nullptr, &ctx->device_);
  if (r != VK_SUCCESS)
    return R::fail("vkCreateDevice on '" + ctx->info_.name + "' failed: " + vk_result_name(r));
  vkGetDeviceQueue(ctx->device_, ctx->family_, 0, &ctx->queue_);

  VkCommandPoolCreateInfo pi{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
  pi.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  pi.queueFamilyIndex = ctx->family_;
  VK_CHECK(vkCreateCommandPool(ctx->device_, &pi, nullptr, &ctx->pool_));
  VkFenceCreateInfo fi{VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
  VK_CHECK(vkCreateFence(ctx->device_, &fi, nullptr, &ctx->fence_));
  return R::ok(std::move(ctx));
}

VulkanContext::~VulkanContext() {
  if (device_) {
    vkDeviceWaitIdle(device_);
    if (fence_) vkDestroyFence(device_, fence_, nullptr);
    if (pool_) vkDestroyCommandPool(device_, pool_, nullptr);
    vkDestroyDevice(device_, nullptr);
  }
  if (messenger_) {
    auto destroy = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(instance_, "vkDestroyDebugUtilsMessengerEXT"));
    if (destroy) destroy(instance_, messenger_, nullptr);
  }
  if (instance_) vkDestroyInstance(instance_, nullptr);
}

VkCommandBuffer VulkanContext::begin_commands() {
  VkCommandBufferAllocateInfo ai{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
  ai.commandPool = pool_;
  ai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  ai.commandBufferCount = 1;
  VkCommandBuffer cmd;
  VK_CHECK(vkAllocateCommandBuffers(device_, &ai, &cmd));
  VkCommandBufferBeginInfo bi{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  VK_CHECK(vkBeginCommandBuffer(cmd, &bi));
  return cmd;
}

double VulkanContext::submit_and_wait(VkCommandBuffer cmd) { return submit_and_wait(cmd, {}); }

double VulkanContext::submit_and_wait(VkCommandBuffer cmd, const std::function<void()>& meanwhile) {
  VK_CHECK(vkEndCommandBuffer(cmd));
  VkSubmitInfo si{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  si.commandBufferCount = 1;
  si.pCommandBuffers = &cmd;
  VK_CHECK(vkResetFences(device_, 1, &fence_));
  const auto t0 = std::chrono::steady_clock::now();
  VK_CHECK(vkQueueSubmit(queue_, 1, &si, fence_));
  if (meanwhile) {
    try {
      meanwhile();
    } catch (...) {
      (void)vkWaitForFences(device_, 1, &fence_, VK_TRUE, UINT64_MAX);  // the first error is the one passed on
      vkFreeCommandBuffers(device_, pool_, 1, &cmd);
      throw;
    }
  }
  VK_CHECK(vkWaitForFences(device_, 1, &fence_, VK_TRUE, UINT64_MAX));
  const auto t1 = std::chrono::steady_clock::now();
  vkFreeCommandBuffers(device_, pool_, 1, &cmd);
  return std::chrono::duration<double, std::milli>(t1 - t0).count();
}

}  // namespace isotouch::engine
