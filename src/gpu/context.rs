//! The headless Vulkan device layer: loader, instance (with the Khronos validation layer and
//! a debug messenger when asked), physical-device choice, one graphics queue, the
//! gpu-allocator instance, the pipeline cache, object naming, idle waits (counted) and a
//! one-shot submission for uploads. Frames in flight live in `frames.rs`.
//!
//! Headless is the default and this module knows no surface. Presentation is an optional
//! extra for the viewer: [`Instance::with_surface_extensions`] adds the window system's
//! surface extensions, and `swapchain.rs` builds a presenting device through
//! [`Device::with_requirements`] (a queue family that presents, `VK_KHR_swapchain`).
//!
//! Ownership is a chain of `Arc`s so destruction order is enforced by the types: every
//! resource holds an `Arc<Device>`, the device holds an `Arc<Instance>`, and each `Drop`
//! destroys its own handle before the fields it depends on are released.

use std::ffi::{c_char, c_void, CStr, CString};
use std::mem::ManuallyDrop;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, RwLock};

use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};

use super::pipeline_cache::{self, CacheIdentity, CacheLoad};
use crate::{Error, Result};

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";
/// `pMessageIdName` of messages from the Vulkan loader itself.
const LOADER_MESSAGE_ID: &str = "Loader Message";

/// GPU allocations found still alive when a [`Device`] was destroyed, over the whole
/// process (gpu-allocator's report at teardown). Tests assert it stays 0.
static LEAKED_ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

/// Allocations leaked by devices destroyed so far in this process.
pub fn leaked_allocations() -> usize {
    LEAKED_ALLOCATIONS.load(Ordering::SeqCst)
}

/// Counts validation WARNING/ERROR messages (the "canary" of wgpu's test suite): tests fail
/// when it is non-zero. The first few messages are kept for the failure report.
#[derive(Debug, Default)]
pub struct Canary {
    count: AtomicUsize,
    messages: Mutex<Vec<String>>,
}

impl Canary {
    /// Messages seen so far.
    pub fn count(&self) -> usize {
        self.count.load(Ordering::SeqCst)
    }

    /// Text of the first messages (at most 16).
    pub fn messages(&self) -> Vec<String> {
        lock(&self.messages).clone()
    }

    fn record(&self, text: String) {
        self.count.fetch_add(1, Ordering::SeqCst);
        let mut m = lock(&self.messages);
        if m.len() < 16 {
            m.push(text);
        }
    }
}

/// Locks a mutex, recovering the data if a panicking thread poisoned it (the guarded data
/// here stays consistent across a panic: counters and append-only lists).
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Debug-utils callback: prints the message and feeds the canary.
///
/// # Safety
/// Called by the Vulkan loader with a valid callback-data pointer and the `user_data` given
/// at messenger creation, which points at the `Canary` owned by the live [`Instance`].
unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user_data: *mut c_void,
) -> vk::Bool32 {
    // SAFETY: the loader passes a valid pointer (or null, handled) for the duration of the
    // call; its strings are NUL-terminated per the VkDebugUtilsMessengerCallbackDataEXT rules.
    let (id, msg) = match unsafe { data.as_ref() } {
        Some(d) => unsafe {
            (
                d.message_id_name_as_c_str()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default(),
                d.message_as_c_str()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default(),
            )
        },
        None => (String::new(), String::new()),
    };
    let text = format!("[vulkan {severity:?} {types:?}] {id}: {msg}");
    eprintln!("{text}");
    // Suppressed: "Loader Message" reports problems of *other* installed drivers (e.g. an
    // NVIDIA ICD without graphics support inside a compute container) through the same
    // messenger. They say nothing about this program's API use, and a missing driver
    // surfaces as an error of its own (NoVulkan).
    if id == LOADER_MESSAGE_ID {
        return vk::FALSE;
    }
    // SAFETY: user_data is `Arc::as_ptr` of the Canary the Instance keeps alive until after
    // the messenger is destroyed.
    if let Some(canary) = unsafe { (user_data as *const Canary).as_ref() } {
        canary.record(text);
    }
    vk::FALSE
}

/// Loader + instance + optional debug messenger.
pub struct Instance {
    entry: ash::Entry,
    pub(crate) raw: ash::Instance,
    messenger: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    debug_utils_enabled: bool,
    canary: Arc<Canary>,
}

impl Instance {
    /// Loads Vulkan and creates an instance. With `validation`, the Khronos validation layer
    /// (with synchronisation validation when available) and a WARNING/ERROR messenger are
    /// enabled; a missing layer is an error then, not a silent downgrade.
    pub fn new(validation: bool) -> Result<Arc<Self>> {
        Self::create(validation, &[])
    }

    /// [`Instance::new`] plus the surface extensions the window system of `display` needs
    /// (`VK_KHR_surface` and e.g. `VK_KHR_xlib_surface`). A loader without them is
    /// [`Error::NoPresentation`].
    pub fn with_surface_extensions(
        validation: bool,
        display: raw_window_handle::RawDisplayHandle,
    ) -> Result<Arc<Self>> {
        let required = ash_window::enumerate_required_extensions(display).map_err(|e| {
            Error::NoPresentation(format!("no Vulkan surface for this window system ({e})"))
        })?;
        Self::create(validation, required)
    }

    /// The instance: the loader checked ([`load_entry`]), the layers and extensions chosen
    /// ([`InstanceSetup::choose`]), the instance created with the validation messenger
    /// chained, then the messenger that outlives creation attached.
    fn create(validation: bool, surface_extensions: &[*const c_char]) -> Result<Arc<Self>> {
        let entry = load_entry()?;
        let setup = InstanceSetup::choose(&entry, validation, surface_extensions)?;
        let canary = Arc::new(Canary::default());
        let mut messenger_info = messenger_info(&canary);
        let enabled_features = [vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
        let mut validation_features =
            vk::ValidationFeaturesEXT::default().enabled_validation_features(&enabled_features);

        let app = vk::ApplicationInfo::default()
            .application_name(c"diffract")
            .application_version(1)
            .engine_name(c"diffract")
            .api_version(vk::API_VERSION_1_1);
        let mut create_info = vk::InstanceCreateInfo::default()
            .application_info(&app)
            .enabled_layer_names(&setup.layers)
            .enabled_extension_names(&setup.extensions);
        if validation {
            // Chained so that messages of vkCreateInstance/vkDestroyInstance are caught too.
            create_info = create_info.push_next(&mut messenger_info);
            if setup.sync_validation {
                create_info = create_info.push_next(&mut validation_features);
            }
        }
        // SAFETY: every pointer in create_info (names, chained structs) outlives this call.
        let raw = unsafe { entry.create_instance(&create_info, None) }.map_err(|e| match e {
            vk::Result::ERROR_INCOMPATIBLE_DRIVER => Error::NoVulkan(
                "the Vulkan loader found no usable driver (vkCreateInstance: \
                 VK_ERROR_INCOMPATIBLE_DRIVER)"
                    .into(),
            ),
            e => Error::vk("vkCreateInstance")(e),
        })?;

        let mut instance = Instance {
            entry,
            raw,
            messenger: None,
            debug_utils_enabled: setup.debug_utils_enabled,
            canary,
        };
        if validation {
            let loader = ash::ext::debug_utils::Instance::new(&instance.entry, &instance.raw);
            // messenger_info was consumed by the chain only as a pointer; reuse its fields.
            let info = vk::DebugUtilsMessengerCreateInfoEXT {
                p_next: std::ptr::null(),
                ..messenger_info
            };
            // SAFETY: the instance is live and the callback's user_data (the canary) lives
            // as long as `instance`, which destroys the messenger first in Drop.
            let m = unsafe { loader.create_debug_utils_messenger(&info, None) }
                .map_err(Error::vk("vkCreateDebugUtilsMessengerEXT"))?;
            instance.messenger = Some((loader, m));
        }
        Ok(Arc::new(instance))
    }

    /// The validation canary (counts WARNING/ERROR messages).
    pub fn canary(&self) -> &Arc<Canary> {
        &self.canary
    }

    /// The loader's entry points (surface creation needs them).
    pub(crate) fn entry(&self) -> &ash::Entry {
        &self.entry
    }
}

/// The system's Vulkan loader, refused below version 1.1.
fn load_entry() -> Result<ash::Entry> {
    // SAFETY: loading the system Vulkan library runs its initialisers; we trust the
    // installed loader like any Vulkan application does.
    let entry = unsafe { ash::Entry::load() }
        .map_err(|e| Error::NoVulkan(format!("cannot load the Vulkan loader: {e}")))?;

    // SAFETY: entry is a loaded Vulkan entry point table.
    let version = unsafe { entry.try_enumerate_instance_version() }
        .map_err(Error::vk("vkEnumerateInstanceVersion"))?
        .unwrap_or(vk::API_VERSION_1_0);
    if version < vk::API_VERSION_1_1 {
        return Err(Error::NoVulkan(format!(
            "the Vulkan loader supports only version {}.{}; 1.1 is needed",
            vk::api_version_major(version),
            vk::api_version_minor(version)
        )));
    }
    Ok(entry)
}

/// The instance's layers and extensions.
struct InstanceSetup {
    layers: Vec<*const c_char>,
    extensions: Vec<*const c_char>,
    debug_utils_enabled: bool,
    /// The validation layer offers synchronisation validation.
    sync_validation: bool,
}

impl InstanceSetup {
    /// The window system's surface extensions (each must be present), debug utils where
    /// available (required with `validation`), and with `validation` the Khronos layer and
    /// its synchronisation validation where offered.
    fn choose(
        entry: &ash::Entry,
        validation: bool,
        surface_extensions: &[*const c_char],
    ) -> Result<Self> {
        // SAFETY: plain enumeration calls on a loaded entry.
        let available = unsafe { entry.enumerate_instance_extension_properties(None) }
            .map_err(Error::vk("vkEnumerateInstanceExtensionProperties"))?;
        let has_ext = |list: &[vk::ExtensionProperties], name: &CStr| {
            list.iter()
                .any(|e| e.extension_name_as_c_str().is_ok_and(|n| n == name))
        };
        let debug_utils_enabled = has_ext(&available, ash::ext::debug_utils::NAME);
        if validation && !debug_utils_enabled {
            return Err(Error::invalid(
                "validation",
                "VK_EXT_debug_utils is not available, so validation messages cannot be collected",
            ));
        }
        let mut layers: Vec<*const c_char> = Vec::new();
        let mut extensions: Vec<*const c_char> = Vec::new();
        for &name in surface_extensions {
            // SAFETY: ash_window returns pointers to NUL-terminated 'static extension names.
            let name_c = unsafe { CStr::from_ptr(name) };
            if !has_ext(&available, name_c) {
                return Err(Error::NoPresentation(format!(
                    "the Vulkan loader lacks {}",
                    name_c.to_string_lossy()
                )));
            }
            extensions.push(name);
        }
        if debug_utils_enabled {
            extensions.push(ash::ext::debug_utils::NAME.as_ptr());
        }
        let mut sync_validation = false;
        if validation {
            // SAFETY: plain enumeration call on a loaded entry.
            let present = unsafe { entry.enumerate_instance_layer_properties() }
                .map_err(Error::vk("vkEnumerateInstanceLayerProperties"))?;
            if !present
                .iter()
                .any(|l| l.layer_name_as_c_str().is_ok_and(|n| n == VALIDATION_LAYER))
            {
                return Err(Error::invalid(
                    "validation",
                    "VK_LAYER_KHRONOS_validation is not installed (e.g. apt install vulkan-validationlayers)",
                ));
            }
            layers.push(VALIDATION_LAYER.as_ptr());
            // SAFETY: enumeration of the extensions a present layer provides.
            let layer_exts =
                unsafe { entry.enumerate_instance_extension_properties(Some(VALIDATION_LAYER)) }
                    .map_err(Error::vk("vkEnumerateInstanceExtensionProperties"))?;
            if has_ext(&layer_exts, ash::ext::validation_features::NAME) {
                extensions.push(ash::ext::validation_features::NAME.as_ptr());
                sync_validation = true;
            }
        }
        Ok(Self {
            layers,
            extensions,
            debug_utils_enabled,
            sync_validation,
        })
    }
}

/// The validation messenger: warnings and errors of every type, counted by `canary`.
fn messenger_info(canary: &Arc<Canary>) -> vk::DebugUtilsMessengerCreateInfoEXT<'static> {
    vk::DebugUtilsMessengerCreateInfoEXT::default()
        .message_severity(
            vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
        )
        .message_type(
            vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
        )
        .pfn_user_callback(Some(debug_callback))
        .user_data(Arc::as_ptr(canary) as *mut c_void)
}

impl Drop for Instance {
    fn drop(&mut self) {
        if let Some((loader, m)) = self.messenger.take() {
            // SAFETY: created from this instance, destroyed once; no callbacks are pending
            // because all devices (which hold an Arc to us) are gone.
            unsafe { loader.destroy_debug_utils_messenger(m, None) };
        }
        // SAFETY: every child object was destroyed: devices and resources keep an Arc to
        // this instance, so this runs only after them.
        unsafe { self.raw.destroy_instance(None) };
    }
}

/// What we know about the chosen physical device.
#[derive(Debug, Clone)]
pub struct DeviceInfo {
    /// `deviceName` of the driver.
    pub name: String,
    pub device_type: vk::PhysicalDeviceType,
    /// Nanoseconds per timestamp tick.
    pub timestamp_period: f64,
    /// Valid bits of timestamps on the graphics queue; 0 means no timestamps.
    pub timestamp_valid_bits: u32,
    /// Largest 2D image side.
    pub max_image_dimension_2d: u32,
    /// Largest side of a 3D image.
    pub max_image_dimension_3d: u32,
    /// Largest number of image array layers.
    pub max_image_array_layers: u32,
    /// Whether `shaderFloat64` is supported (and then enabled): float64 in shaders.
    pub shader_float64: bool,
}

impl DeviceInfo {
    /// The most loop iterations one shader invocation may run, over all its loops together,
    /// before the driver ends them early and silently: llvmpipe (lavapipe) counts them
    /// against gallivm's `LP_MAX_TGSI_LOOP_ITERATIONS` (65 535). `None` where the driver
    /// has no such limit (GPUs).
    pub fn loop_iteration_limit(&self) -> Option<u64> {
        self.name.starts_with("llvmpipe").then_some(65_535)
    }
}

/// A logical device with one graphics queue, a command pool and the memory allocator.
pub struct Device {
    pub(crate) raw: ash::Device,
    pub(crate) physical: vk::PhysicalDevice,
    pub(crate) queue: vk::Queue,
    pub(crate) queue_family: u32,
    pub info: DeviceInfo,
    /// The one-shot pool of `submit_once`, externally synchronised by its lock.
    command_pool: vk::CommandPool,
    one_shot_pool_lock: Mutex<()>,
    /// The queue must be externally synchronised (Vulkan spec, "Threading Behavior");
    /// `Device` is shared through `Arc`, so submissions and presents take this lock.
    submit_lock: Mutex<()>,
    allocator: ManuallyDrop<Mutex<Allocator>>,
    debug: Option<ash::ext::debug_utils::Device>,
    /// Used by every pipeline creation. Creation is internally synchronised; merging a file
    /// into it is not (`vkMergePipelineCaches`: dstCache), hence the lock (read: create).
    pipeline_cache: vk::PipelineCache,
    pipeline_cache_lock: RwLock<()>,
    /// Where the cache is saved when the device is dropped (none: in memory only).
    pipeline_cache_file: Mutex<Option<PathBuf>>,
    cache_identity: CacheIdentity,
    /// `vkDeviceWaitIdle` calls so far (the frame path must make none).
    idle_waits: AtomicUsize,
    /// Kept last: the instance must outlive the device.
    instance: Arc<Instance>,
}

/// What a device must offer beyond a graphics queue, for [`Device::with_requirements`]
/// (presentation: a queue family that presents to a surface and `VK_KHR_swapchain`).
pub struct Requirements<'a> {
    /// Whether queue family `family` of `pd` may be the device's one queue family.
    pub queue_family: &'a dyn Fn(vk::PhysicalDevice, u32) -> bool,
    /// Device extensions to enable; devices without them are skipped.
    pub extensions: &'a [&'a CStr],
    /// The error when no device meets the requirements.
    pub unmet: &'a dyn Fn() -> Error,
}

/// Whether physical device `pd` offers device extension `name`.
fn device_has_extension(inst: &ash::Instance, pd: vk::PhysicalDevice, name: &CStr) -> bool {
    // SAFETY: pd was enumerated from this live instance.
    unsafe { inst.enumerate_device_extension_properties(pd) }.is_ok_and(|list| {
        list.iter()
            .any(|e| e.extension_name_as_c_str().is_ok_and(|n| n == name))
    })
}

/// Preference order of device types: discrete, integrated, virtual, CPU (lavapipe), other.
fn type_rank(t: vk::PhysicalDeviceType) -> u32 {
    match t {
        vk::PhysicalDeviceType::DISCRETE_GPU => 0,
        vk::PhysicalDeviceType::INTEGRATED_GPU => 1,
        vk::PhysicalDeviceType::VIRTUAL_GPU => 2,
        vk::PhysicalDeviceType::CPU => 3,
        _ => 4,
    }
}

/// The physical device a [`Device`] is made on, with its graphics queue family.
struct ChosenPhysical {
    physical: vk::PhysicalDevice,
    queue_family: u32,
    props: vk::PhysicalDeviceProperties,
}

/// The best-ranked (discrete first) Vulkan 1.1 device with a graphics queue that meets
/// `req`: its queue family and extensions.
fn choose_physical(inst: &ash::Instance, req: Option<&Requirements<'_>>) -> Result<ChosenPhysical> {
    // SAFETY: inst is a live instance.
    let physicals = unsafe { inst.enumerate_physical_devices() }
        .map_err(Error::vk("vkEnumeratePhysicalDevices"))?;
    let mut best: Option<(u32, ChosenPhysical)> = None;
    for pd in physicals {
        // SAFETY: pd was enumerated from this instance.
        let props = unsafe { inst.get_physical_device_properties(pd) };
        if props.api_version < vk::API_VERSION_1_1 {
            continue;
        }
        // SAFETY: as above.
        let families = unsafe { inst.get_physical_device_queue_family_properties(pd) };
        let Some(family) = families.iter().enumerate().position(|(i, f)| {
            f.queue_flags.contains(vk::QueueFlags::GRAPHICS)
                && req.is_none_or(|r| (r.queue_family)(pd, i as u32))
        }) else {
            continue;
        };
        if req.is_some_and(|r| {
            r.extensions
                .iter()
                .any(|e| !device_has_extension(inst, pd, e))
        }) {
            continue;
        }
        let rank = type_rank(props.device_type);
        if best.as_ref().is_none_or(|b| rank < b.0) {
            let chosen = ChosenPhysical {
                physical: pd,
                queue_family: family as u32,
                props,
            };
            best = Some((rank, chosen));
        }
    }
    match (best, req) {
        (Some((_, chosen)), _) => Ok(chosen),
        (None, Some(r)) => Err((r.unmet)()),
        (None, None) => Err(Error::NoVulkan(
            "no Vulkan 1.1 device with a graphics queue was found".into(),
        )),
    }
}

/// The logical device: one graphics queue, the required extensions, and float64 in
/// compute shaders (the device table build) where the device has it (the second value).
fn create_logical(
    inst: &ash::Instance,
    chosen: &ChosenPhysical,
    req: Option<&Requirements<'_>>,
) -> Result<(ash::Device, bool)> {
    let priorities = [1.0f32];
    let queue_info = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(chosen.queue_family)
        .queue_priorities(&priorities)];
    let device_exts: Vec<*const c_char> = req
        .map(|r| r.extensions.iter().map(|e| e.as_ptr()).collect())
        .unwrap_or_default();
    // SAFETY: physical is a valid handle of this instance.
    let supported = unsafe { inst.get_physical_device_features(chosen.physical) };
    let shader_float64 = supported.shader_float64 == vk::TRUE;
    let features = vk::PhysicalDeviceFeatures::default().shader_float64(shader_float64);
    let create_info = vk::DeviceCreateInfo::default()
        .queue_create_infos(&queue_info)
        .enabled_extension_names(&device_exts)
        .enabled_features(&features);
    // SAFETY: create_info and its arrays outlive the call; the only feature requested
    // (shaderFloat64) was checked to be supported, and the required extensions were
    // checked to exist.
    let raw = unsafe { inst.create_device(chosen.physical, &create_info, None) }
        .map_err(Error::vk("vkCreateDevice"))?;
    Ok((raw, shader_float64))
}

/// What the device owns besides its queue: the allocator, the one-shot command pool and
/// the pipeline cache. On failure everything made so far, `raw` included, is destroyed.
fn create_owned(
    inst: &ash::Instance,
    raw: &ash::Device,
    physical: vk::PhysicalDevice,
    queue_family: u32,
) -> Result<(Allocator, vk::CommandPool, vk::PipelineCache)> {
    // The default settings already log leaks on shutdown; make sure they stay on.
    let mut debug_settings = gpu_allocator::AllocatorDebugSettings::default();
    debug_settings.log_leaks_on_shutdown = true;
    let allocator = Allocator::new(&AllocatorCreateDesc {
        instance: inst.clone(),
        device: raw.clone(),
        physical_device: physical,
        debug_settings,
        buffer_device_address: false,
        allocation_sizes: Default::default(),
    });
    let allocator = match allocator {
        Ok(a) => a,
        Err(e) => {
            // SAFETY: nothing was created on the device yet.
            unsafe { raw.destroy_device(None) };
            return Err(e.into());
        }
    };

    let pool_info = vk::CommandPoolCreateInfo::default()
        .queue_family_index(queue_family)
        .flags(vk::CommandPoolCreateFlags::TRANSIENT);
    // SAFETY: raw is a live device; the family index is valid.
    let command_pool = match unsafe { raw.create_command_pool(&pool_info, None) } {
        Ok(p) => p,
        Err(e) => {
            drop(allocator);
            // SAFETY: the allocator (which frees its blocks) is gone; nothing else lives.
            unsafe { raw.destroy_device(None) };
            return Err(Error::vk("vkCreateCommandPool")(e));
        }
    };

    // SAFETY: live device; an empty cache (initial data is merged in later from a file,
    // Device::load_pipeline_cache).
    let pipeline_cache =
        match unsafe { raw.create_pipeline_cache(&vk::PipelineCacheCreateInfo::default(), None) } {
            Ok(c) => c,
            Err(e) => {
                // SAFETY: only the pool and the allocator's blocks exist; freed in order.
                unsafe { raw.destroy_command_pool(command_pool, None) };
                drop(allocator);
                // SAFETY: nothing else lives on the device.
                unsafe { raw.destroy_device(None) };
                return Err(Error::vk("vkCreatePipelineCache")(e));
            }
        };
    Ok((allocator, command_pool, pipeline_cache))
}

impl Device {
    /// Creates an instance (see [`Instance::new`]) and a device on the preferred GPU.
    pub fn new(validation: bool) -> Result<Arc<Self>> {
        let instance = Instance::new(validation)?;
        Self::on(instance)
    }

    /// Picks a physical device with a graphics queue and Vulkan ≥ 1.1 and creates the
    /// logical device on it.
    pub fn on(instance: Arc<Instance>) -> Result<Arc<Self>> {
        Self::create(instance, None)
    }

    /// Like [`Device::on`], for a device that must meet `req` too (presentation: see
    /// `Device::on_surface` in `swapchain.rs`).
    pub fn with_requirements(instance: Arc<Instance>, req: &Requirements<'_>) -> Result<Arc<Self>> {
        Self::create(instance, Some(req))
    }

    /// The device: the best physical device that meets `req` ([`choose_physical`]), the
    /// logical device with one graphics queue ([`create_logical`]), its allocator, one-shot
    /// command pool and pipeline cache ([`create_owned`]).
    fn create(instance: Arc<Instance>, req: Option<&Requirements<'_>>) -> Result<Arc<Self>> {
        let inst = &instance.raw;
        let chosen = choose_physical(inst, req)?;
        let (physical, queue_family, props) = (chosen.physical, chosen.queue_family, chosen.props);
        // SAFETY: physical is a valid handle of this instance.
        let families = unsafe { inst.get_physical_device_queue_family_properties(physical) };
        let timestamp_valid_bits = if props.limits.timestamp_compute_and_graphics == vk::TRUE {
            families[queue_family as usize].timestamp_valid_bits
        } else {
            0
        };
        let name = props
            .device_name_as_c_str()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|_| "unnamed device".into());
        let (raw, shader_float64) = create_logical(inst, &chosen, req)?;
        // SAFETY: one queue of this family was requested.
        let queue = unsafe { raw.get_device_queue(queue_family, 0) };
        let (allocator, command_pool, pipeline_cache) =
            create_owned(inst, &raw, physical, queue_family)?;
        let cache_identity = CacheIdentity {
            vendor_id: props.vendor_id,
            device_id: props.device_id,
            driver_version: props.driver_version,
            uuid: props.pipeline_cache_uuid,
        };
        let debug = instance
            .debug_utils_enabled
            .then(|| ash::ext::debug_utils::Device::new(inst, &raw));
        let device = Device {
            raw,
            physical,
            queue,
            queue_family,
            info: DeviceInfo {
                name,
                device_type: props.device_type,
                timestamp_period: props.limits.timestamp_period as f64,
                timestamp_valid_bits,
                max_image_dimension_2d: props.limits.max_image_dimension2_d,
                max_image_dimension_3d: props.limits.max_image_dimension3_d,
                max_image_array_layers: props.limits.max_image_array_layers,
                shader_float64,
            },
            command_pool,
            one_shot_pool_lock: Mutex::new(()),
            submit_lock: Mutex::new(()),
            allocator: ManuallyDrop::new(Mutex::new(allocator)),
            debug,
            pipeline_cache,
            pipeline_cache_lock: RwLock::new(()),
            pipeline_cache_file: Mutex::new(None),
            cache_identity,
            idle_waits: AtomicUsize::new(0),
            instance,
        };
        device.set_name(device.queue, "graphics queue");
        device.set_name(device.command_pool, "one-shot command pool");
        device.set_name(device.pipeline_cache, "pipeline cache");
        Ok(Arc::new(device))
    }

    /// The instance this device was created on.
    pub fn instance(&self) -> &Arc<Instance> {
        &self.instance
    }

    /// The physical device in use.
    pub fn physical(&self) -> vk::PhysicalDevice {
        self.physical
    }

    /// The graphics queue (callers that submit outside [`Device::submit_once`] hold
    /// [`Device::queue_lock`] while doing so).
    pub fn queue(&self) -> vk::Queue {
        self.queue
    }

    /// The lock that externally synchronises the queue (Vulkan spec, "Threading Behavior").
    pub fn queue_lock(&self) -> MutexGuard<'_, ()> {
        lock(&self.submit_lock)
    }

    /// The `ash` device table.
    pub fn raw(&self) -> &ash::Device {
        &self.raw
    }

    /// The graphics queue family (a swapchain must be presentable from it).
    pub fn queue_family(&self) -> u32 {
        self.queue_family
    }

    /// The instance's validation canary; it outlives the device, so messages raised while
    /// the device is destroyed (objects left alive) can still be checked.
    pub fn canary(&self) -> Arc<Canary> {
        Arc::clone(&self.instance.canary)
    }

    /// Validation messages (WARNING/ERROR) seen on this device's instance so far.
    pub fn validation_messages(&self) -> usize {
        self.instance.canary.count()
    }

    /// The first validation messages, for failure reports.
    pub fn validation_report(&self) -> Vec<String> {
        self.instance.canary.messages()
    }

    /// Names a Vulkan object for validation messages and captures (no-op without
    /// VK_EXT_debug_utils). Naming is best effort: a failure only loses the label.
    pub fn set_name<H: vk::Handle>(&self, handle: H, name: &str) {
        let Some(debug) = &self.debug else { return };
        let Ok(name) = CString::new(name) else { return };
        let info = vk::DebugUtilsObjectNameInfoEXT::default()
            .object_handle(handle)
            .object_name(&name);
        // SAFETY: handle belongs to this device and name outlives the call.
        let _ = unsafe { debug.set_debug_utils_object_name(&info) };
    }

    /// Opens a labelled region in a command buffer (shown by captures and validation).
    pub fn begin_label(&self, cb: vk::CommandBuffer, label: &str) {
        let Some(debug) = &self.debug else { return };
        let Ok(label) = CString::new(label) else {
            return;
        };
        let info = vk::DebugUtilsLabelEXT::default().label_name(&label);
        // SAFETY: cb is in the recording state (callers only label while recording).
        unsafe { debug.cmd_begin_debug_utils_label(cb, &info) };
    }

    /// Closes the region opened by [`Device::begin_label`].
    pub fn end_label(&self, cb: vk::CommandBuffer) {
        let Some(debug) = &self.debug else { return };
        // SAFETY: matches a begin_label on the same recording command buffer.
        unsafe { debug.cmd_end_debug_utils_label(cb) };
    }

    /// Locks the allocator.
    pub(crate) fn allocator(&self) -> MutexGuard<'_, Allocator> {
        lock(&self.allocator)
    }

    /// Whether `format` supports `features` with optimal tiling.
    pub fn supports_format(&self, format: vk::Format, features: vk::FormatFeatureFlags) -> bool {
        // SAFETY: physical belongs to the live instance.
        let props = unsafe {
            self.instance
                .raw
                .get_physical_device_format_properties(self.physical, format)
        };
        props.optimal_tiling_features.contains(features)
    }

    /// `vkDeviceWaitIdle`, counted ([`Device::idle_waits`]). For teardown and error paths
    /// only: frames in flight retire objects through `Frames::retire` instead.
    pub fn wait_idle(&self) -> Result<()> {
        let _queue = self.queue_lock();
        self.idle_waits.fetch_add(1, Ordering::SeqCst);
        // SAFETY: live device; the queue is externally synchronised by the lock.
        unsafe { self.raw.device_wait_idle() }.map_err(Error::vk("vkDeviceWaitIdle"))
    }

    /// How many times [`Device::wait_idle`] ran on this device (tests check that the
    /// viewer's frame path makes no idle wait).
    pub fn idle_waits(&self) -> usize {
        self.idle_waits.load(Ordering::SeqCst)
    }

    /// Runs `create` with the device's pipeline cache (every pipeline creation goes through
    /// here).
    pub(crate) fn with_pipeline_cache<R>(&self, create: impl FnOnce(vk::PipelineCache) -> R) -> R {
        let _read = self
            .pipeline_cache_lock
            .read()
            .unwrap_or_else(|p| p.into_inner());
        create(self.pipeline_cache)
    }

    /// Merges the pipeline cache file of this GPU in `dir` (beside the term cache) into the
    /// device's cache, and saves the cache there when the device is dropped. A missing,
    /// damaged or foreign file is not an error ([`CacheLoad`] says what happened); only the
    /// first directory given is used.
    pub fn load_pipeline_cache(&self, dir: &Path) -> CacheLoad {
        let path = pipeline_cache::cache_path(dir, &self.cache_identity);
        {
            let mut file = lock(&self.pipeline_cache_file);
            if file.is_some() {
                return CacheLoad::Ignored("a pipeline cache file is already in use".into());
            }
            *file = Some(path.clone());
        }
        let bytes = match crate::fsutil::read_bounded(
            &path,
            "pipeline cache",
            pipeline_cache::MAX_CACHE_BYTES,
        ) {
            Ok(b) => b,
            Err(Error::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => {
                return CacheLoad::Missing
            }
            Err(e) => return CacheLoad::Ignored(e.to_string()),
        };
        let data = match pipeline_cache::decode(&self.cache_identity, &bytes) {
            Ok(d) => d,
            Err(why) => return CacheLoad::Ignored(why),
        };
        let info = vk::PipelineCacheCreateInfo::default().initial_data(data);
        // SAFETY: live device; data passed both header checks (ours and Vulkan's).
        let loaded = match unsafe { self.raw.create_pipeline_cache(&info, None) } {
            Ok(c) => c,
            Err(e) => return CacheLoad::Ignored(format!("vkCreatePipelineCache: {e}")),
        };
        let merged = {
            let _write = self
                .pipeline_cache_lock
                .write()
                .unwrap_or_else(|p| p.into_inner());
            // SAFETY: the write lock synchronises dstCache; both caches are live.
            unsafe {
                self.raw
                    .merge_pipeline_caches(self.pipeline_cache, &[loaded])
            }
        };
        // SAFETY: the source cache is used by nothing else.
        unsafe { self.raw.destroy_pipeline_cache(loaded, None) };
        match merged {
            Ok(()) => CacheLoad::Loaded(data.len()),
            Err(e) => CacheLoad::Ignored(format!("vkMergePipelineCaches: {e}")),
        }
    }

    /// Writes the pipeline cache to its file (atomically: a temporary file renamed into
    /// place). `Ok(None)` without a file ([`Device::load_pipeline_cache`] not called).
    pub fn save_pipeline_cache(&self) -> Result<Option<PathBuf>> {
        let Some(path) = lock(&self.pipeline_cache_file).clone() else {
            return Ok(None);
        };
        let data = self.with_pipeline_cache(|cache| {
            // SAFETY: live cache of this device.
            unsafe { self.raw.get_pipeline_cache_data(cache) }
        });
        let data = data.map_err(Error::vk("vkGetPipelineCacheData"))?;
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        }
        crate::fsutil::write_atomic(&path, &pipeline_cache::encode(&self.cache_identity, &data))?;
        Ok(Some(path))
    }

    /// Records commands with `record`, submits them and waits for completion. Everything
    /// the commands used may be destroyed once this returns. For one-off uploads; repeated
    /// work (frames) goes through `Frames`.
    pub fn submit_once(
        &self,
        label: &str,
        record: impl FnOnce(vk::CommandBuffer) -> Result<()>,
    ) -> Result<()> {
        let cb = {
            let _pool = lock(&self.one_shot_pool_lock);
            let alloc_info = vk::CommandBufferAllocateInfo::default()
                .command_pool(self.command_pool)
                .level(vk::CommandBufferLevel::PRIMARY)
                .command_buffer_count(1);
            // SAFETY: the pool belongs to this device and is used only under its lock.
            let cb = unsafe { self.raw.allocate_command_buffers(&alloc_info) }
                .map_err(Error::vk("vkAllocateCommandBuffers"))?[0];
            if let Err(e) = self.record_once(cb, label, record) {
                // SAFETY: never submitted; the pool is locked.
                unsafe { self.raw.free_command_buffers(self.command_pool, &[cb]) };
                return Err(e);
            }
            cb
        };
        let result = self.submit_and_wait(cb, label);
        let _pool = lock(&self.one_shot_pool_lock);
        // SAFETY: the submission finished (or was never made, or the device idled), so cb
        // is not pending; the pool is locked.
        unsafe { self.raw.free_command_buffers(self.command_pool, &[cb]) };
        result
    }

    /// Records `cb` (the one-shot pool's lock held by the caller).
    fn record_once(
        &self,
        cb: vk::CommandBuffer,
        label: &str,
        record: impl FnOnce(vk::CommandBuffer) -> Result<()>,
    ) -> Result<()> {
        self.set_name(cb, label);
        let begin = vk::CommandBufferBeginInfo::default()
            .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        // SAFETY: cb was just allocated and is in the initial state.
        unsafe { self.raw.begin_command_buffer(cb, &begin) }
            .map_err(Error::vk("vkBeginCommandBuffer"))?;
        self.begin_label(cb, label);
        record(cb)?;
        self.end_label(cb);
        // SAFETY: cb is recording.
        unsafe { self.raw.end_command_buffer(cb) }.map_err(Error::vk("vkEndCommandBuffer"))
    }

    /// Submits the recorded `cb` and waits for it. The queue is locked only for the
    /// submission, so frames of other threads go on while an upload runs.
    fn submit_and_wait(&self, cb: vk::CommandBuffer, label: &str) -> Result<()> {
        // SAFETY: live device.
        let fence = unsafe { self.raw.create_fence(&vk::FenceCreateInfo::default(), None) }
            .map_err(Error::vk("vkCreateFence"))?;
        self.set_name(fence, label);
        let cbs = [cb];
        let submit = [vk::SubmitInfo::default().command_buffers(&cbs)];
        let submitted = {
            let _queue = self.queue_lock();
            // SAFETY: cb is executable; the queue is locked; the fence is unsignalled.
            unsafe { self.raw.queue_submit(self.queue, &submit, fence) }
                .map_err(Error::vk("vkQueueSubmit"))
        };
        let result = submitted.and_then(|()| {
            // SAFETY: the fence was submitted above.
            unsafe { self.raw.wait_for_fences(&[fence], true, u64::MAX) }
                .map_err(Error::vk("vkWaitForFences"))
        });
        if result.is_err() {
            // Make sure nothing is still running before the caller frees resources; the
            // error path is already being reported.
            let _ = self.wait_idle();
        }
        // SAFETY: the fence is signalled or the device is idle, so it is not in use.
        unsafe { self.raw.destroy_fence(fence, None) };
        result
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        // Every resource holds an Arc<Device>, so none is alive any more; waiting covers any
        // work still queued.
        let _ = self.wait_idle();
        // A cache is an optimisation: failing to save it costs the next start a recompile.
        let _ = self.save_pipeline_cache();
        // SAFETY: the device is idle; nothing uses the pool or the cache.
        unsafe {
            self.raw.destroy_pipeline_cache(self.pipeline_cache, None);
            self.raw.destroy_command_pool(self.command_pool, None);
        }
        {
            let alloc = lock(&self.allocator);
            let report = alloc.generate_report();
            if !report.allocations.is_empty() {
                // Resources free their memory explicitly; anything left is a bug to fix.
                LEAKED_ALLOCATIONS.fetch_add(report.allocations.len(), Ordering::SeqCst);
                eprintln!(
                    "diffract: {} GPU allocation(s) leaked: {:?}",
                    report.allocations.len(),
                    report
                        .allocations
                        .iter()
                        .map(|a| &a.name)
                        .collect::<Vec<_>>()
                );
            }
        }
        // SAFETY: the allocator is dropped exactly once, here, before the device it frees
        // its memory blocks on.
        unsafe { ManuallyDrop::drop(&mut self.allocator) };
        // SAFETY: all child objects are destroyed (see above).
        unsafe { self.raw.destroy_device(None) };
    }
}
