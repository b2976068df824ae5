//! The few Orbbec SDK v2 C functions the driver needs, loaded at run time with `libloading`, and
//! owning wrappers that delete every SDK object they hold. All `unsafe` of the Orbbec driver lives
//! here. Signatures and struct layouts follow `include/libobsensor/h/*.h` of OrbbecSDK_v2 2.9.x.

#![allow(unsafe_code)]

use std::ffi::{c_char, c_int, CStr, CString};
use std::path::Path;
use std::ptr;
use std::sync::Arc;

use libloading::Library;

macro_rules! opaque {
    ($($name:ident),*) => {$(
        #[repr(C)]
        pub struct $name {
            _private: [u8; 0],
        }
    )*};
}
opaque!(
    ObError,
    ObContext,
    ObDeviceList,
    ObDevice,
    ObDeviceInfo,
    ObPipeline,
    ObConfig,
    ObStreamProfile,
    ObStreamProfileList,
    ObFrame,
    ObFilter
);

type Err = *mut *mut ObError;

/// `ob_camera_intrinsic` (ObTypes.h).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct ObCameraIntrinsic {
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub width: i16,
    pub height: i16,
}

/// `ob_camera_distortion` (ObTypes.h; no padding, so `repr(C)` matches the packed header).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct ObCameraDistortion {
    pub k: [f32; 6],
    pub p1: f32,
    pub p2: f32,
    pub model: c_int,
}

/// `ob_extrinsic`: `p_target = rot * p_source + trans`, rotation row-major, translation in mm.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct ObExtrinsic {
    pub rot: [f32; 9],
    pub trans: [f32; 3],
}

/// `ob_multi_device_sync_config` (ObTypes.h). The header is under `#pragma pack(push, 1)`: the
/// `bool` is followed directly by the next `int` (25 bytes in all), hence `packed`.
#[repr(C, packed)]
#[derive(Debug, Clone, Copy, Default)]
pub struct ObMultiDeviceSyncConfig {
    pub sync_mode: c_int,
    pub depth_delay_us: c_int,
    pub color_delay_us: c_int,
    pub trigger_to_image_delay_us: c_int,
    pub trigger_out_enable: bool,
    pub trigger_out_delay_us: c_int,
    pub frames_per_trigger: c_int,
}

// Enumerators from ObTypes.h.
pub const OB_SENSOR_COLOR: c_int = 2;
pub const OB_SENSOR_DEPTH: c_int = 3;
pub const OB_FRAME_AGGREGATE_OUTPUT_ALL_TYPE_FRAME_REQUIRE: c_int = 0;
pub const OB_STREAM_COLOR: c_int = 2;
// Only for frames built without a camera (the tests against the real library).
#[cfg(test)]
pub const OB_STREAM_DEPTH: c_int = 3;
#[cfg(test)]
pub const OB_FRAME_COLOR: c_int = 2;
#[cfg(test)]
pub const OB_FRAME_DEPTH: c_int = 3;
#[cfg(test)]
pub const OB_DISTORTION_NONE: c_int = 0;
// The OB_MULTI_DEVICE_SYNC_MODE_* bits are `super::sync::MODE_*`.
pub const OB_PERMISSION_READ: c_int = 1;
pub const OB_PERMISSION_WRITE: c_int = 2;
/// `OB_PROP_INTRA_CAMERA_SYNC_REFERENCE_INT` (Property.h), values `ob_intra_camera_sync_reference`.
pub const OB_PROP_INTRA_CAMERA_SYNC_REFERENCE_INT: c_int = 236;
/// `OB_MIDDLE_OF_EXPOSURE`: colour and depth synchronised on the middle of their exposures.
pub const OB_MIDDLE_OF_EXPOSURE: i32 = 1;
/// `OB_PROP_USB_SYNC_VOLTAGE_LEVEL_INT` (Property.h): the USB-C sync pins' I/O voltage level.
pub const OB_PROP_USB_SYNC_VOLTAGE_LEVEL_INT: c_int = 270;
pub const OB_CLOCK_TYPE_MONOTONIC: c_int = 1;
pub const OB_LOG_SEVERITY_WARN: c_int = 2;
pub const OB_LOG_SEVERITY_OFF: c_int = 5;
/// `ob_exception_type` values that mean the camera is gone or absent.
pub const OB_EXCEPTION_TYPE_CAMERA_DISCONNECTED: c_int = 2;
pub const OB_EXCEPTION_TYPE_DEVICE_UNAVAILABLE: c_int = 11;
pub const OB_EXCEPTION_TYPE_NOT_FOUND: c_int = 13;
pub const OB_EXCEPTION_TYPE_INVALID_VALUE: c_int = 4;
pub const OB_EXCEPTION_TYPE_UNSUPPORTED_OPERATION: c_int = 9;

macro_rules! api {
    ($($name:ident: fn($($arg:ty),*) $(-> $ret:ty)?;)*) => {
        /// The loaded library and the functions taken from it. The function pointers stay valid
        /// while `_lib` is alive, which is as long as this struct. (The frame builders are only
        /// called by the tests against the real library.)
        #[allow(dead_code)]
        pub struct Api {
            $($name: unsafe extern "C" fn($($arg),*) $(-> $ret)?,)*
            _lib: Library,
        }

        impl Api {
            fn load(path: &Path) -> Result<Api, String> {
                // SAFETY: loading runs the library's initialisers; libOrbbecSDK's only set up its
                // own globals (no init-order requirements on the host process).
                let lib = unsafe { Library::new(path) }.map_err(|e| e.to_string())?;
                $(
                    // SAFETY: the declared type matches the C prototype in the SDK headers; the
                    // copied pointer is only called while `_lib` (stored alongside) is loaded.
                    let $name = unsafe {
                        *lib.get::<unsafe extern "C" fn($($arg),*) $(-> $ret)?>(
                            concat!(stringify!($name), "\0").as_bytes(),
                        )
                        .map_err(|e| format!("missing symbol {}: {e}", stringify!($name)))?
                    };
                )*
                Ok(Api { $($name,)* _lib: lib })
            }
        }
    };
}

api! {
    ob_get_major_version: fn() -> c_int;
    ob_get_minor_version: fn() -> c_int;
    ob_get_patch_version: fn() -> c_int;
    ob_error_get_status: fn(*const ObError) -> c_int;
    ob_error_get_message: fn(*const ObError) -> *const c_char;
    ob_error_get_function: fn(*const ObError) -> *const c_char;
    ob_error_get_exception_type: fn(*const ObError) -> c_int;
    ob_delete_error: fn(*mut ObError);
    ob_set_logger_to_file: fn(c_int, *const c_char, Err);
    ob_set_logger_to_console: fn(c_int, Err);
    ob_create_context: fn(Err) -> *mut ObContext;
    ob_delete_context: fn(*mut ObContext, Err);
    ob_context_set_timestamp_clock_type: fn(*mut ObContext, c_int, Err);
    ob_query_device_list: fn(*mut ObContext, Err) -> *mut ObDeviceList;
    ob_delete_device_list: fn(*mut ObDeviceList, Err);
    ob_device_list_get_count: fn(*const ObDeviceList, Err) -> u32;
    ob_device_list_get_device: fn(*const ObDeviceList, u32, Err) -> *mut ObDevice;
    ob_device_list_get_device_serial_number: fn(*const ObDeviceList, u32, Err) -> *const c_char;
    ob_delete_device: fn(*mut ObDevice, Err);
    ob_device_get_device_info: fn(*const ObDevice, Err) -> *mut ObDeviceInfo;
    ob_delete_device_info: fn(*mut ObDeviceInfo, Err);
    ob_device_info_get_name: fn(*const ObDeviceInfo, Err) -> *const c_char;
    ob_device_info_get_serial_number: fn(*const ObDeviceInfo, Err) -> *const c_char;
    ob_device_info_get_pid: fn(*const ObDeviceInfo, Err) -> c_int;
    ob_device_info_get_firmware_version: fn(*const ObDeviceInfo, Err) -> *const c_char;
    ob_device_is_property_supported: fn(*const ObDevice, c_int, c_int, Err) -> bool;
    ob_device_set_int_property: fn(*mut ObDevice, c_int, i32, Err);
    ob_device_get_int_property: fn(*mut ObDevice, c_int, Err) -> i32;
    ob_device_get_supported_multi_device_sync_mode_bitmap: fn(*const ObDevice, Err) -> u16;
    ob_device_get_multi_device_sync_config: fn(*const ObDevice, Err) -> ObMultiDeviceSyncConfig;
    ob_device_set_multi_device_sync_config: fn(*mut ObDevice, *const ObMultiDeviceSyncConfig, Err);
    ob_device_trigger_capture: fn(*mut ObDevice, Err);
    ob_device_is_global_timestamp_supported: fn(*const ObDevice, Err) -> bool;
    ob_device_enable_global_timestamp: fn(*mut ObDevice, bool, Err);
    ob_create_pipeline_with_device: fn(*const ObDevice, Err) -> *mut ObPipeline;
    ob_delete_pipeline: fn(*mut ObPipeline, Err);
    ob_pipeline_get_stream_profile_list: fn(*const ObPipeline, c_int, Err) -> *mut ObStreamProfileList;
    ob_stream_profile_list_get_video_stream_profile:
        fn(*const ObStreamProfileList, c_int, c_int, c_int, c_int, Err) -> *mut ObStreamProfile;
    ob_delete_stream_profile_list: fn(*const ObStreamProfileList, Err);
    ob_stream_profile_list_get_count: fn(*const ObStreamProfileList, Err) -> u32;
    ob_stream_profile_list_get_profile: fn(*const ObStreamProfileList, c_int, Err) -> *mut ObStreamProfile;
    ob_stream_profile_get_format: fn(*const ObStreamProfile, Err) -> c_int;
    ob_video_stream_profile_get_fps: fn(*const ObStreamProfile, Err) -> u32;
    ob_delete_stream_profile: fn(*const ObStreamProfile, Err);
    ob_video_stream_profile_get_intrinsic: fn(*const ObStreamProfile, Err) -> ObCameraIntrinsic;
    ob_video_stream_profile_get_distortion: fn(*const ObStreamProfile, Err) -> ObCameraDistortion;
    ob_video_stream_profile_get_width: fn(*const ObStreamProfile, Err) -> u32;
    ob_video_stream_profile_get_height: fn(*const ObStreamProfile, Err) -> u32;
    ob_create_config: fn(Err) -> *mut ObConfig;
    ob_delete_config: fn(*mut ObConfig, Err);
    ob_config_enable_stream_with_stream_profile: fn(*mut ObConfig, *const ObStreamProfile, Err);
    ob_config_set_frame_aggregate_output_mode: fn(*mut ObConfig, c_int, Err);
    ob_pipeline_start_with_config: fn(*mut ObPipeline, *const ObConfig, Err);
    ob_pipeline_stop: fn(*mut ObPipeline, Err);
    ob_pipeline_wait_for_frameset: fn(*mut ObPipeline, u32, Err) -> *mut ObFrame;
    ob_frameset_get_color_frame: fn(*const ObFrame, Err) -> *mut ObFrame;
    ob_frameset_get_depth_frame: fn(*const ObFrame, Err) -> *mut ObFrame;
    ob_delete_frame: fn(*const ObFrame, Err);
    ob_frame_get_format: fn(*const ObFrame, Err) -> c_int;
    ob_frame_get_data: fn(*const ObFrame, Err) -> *mut u8;
    ob_frame_get_data_size: fn(*const ObFrame, Err) -> u32;
    ob_frame_get_timestamp_us: fn(*const ObFrame, Err) -> u64;
    ob_frame_get_system_timestamp_us: fn(*const ObFrame, Err) -> u64;
    ob_frame_get_global_timestamp_us: fn(*const ObFrame, Err) -> u64;
    ob_video_frame_get_width: fn(*const ObFrame, Err) -> u32;
    ob_video_frame_get_height: fn(*const ObFrame, Err) -> u32;
    ob_depth_frame_get_value_scale: fn(*const ObFrame, Err) -> f32;
    ob_create_filter: fn(*const c_char, Err) -> *mut ObFilter;
    ob_delete_filter: fn(*mut ObFilter, Err);
    ob_filter_set_config_value: fn(*mut ObFilter, *const c_char, f64, Err);
    ob_filter_process: fn(*mut ObFilter, *const ObFrame, Err) -> *mut ObFrame;
    ob_create_video_stream_profile: fn(c_int, c_int, u32, u32, u32, Err) -> *mut ObStreamProfile;
    ob_video_stream_profile_set_intrinsic: fn(*mut ObStreamProfile, ObCameraIntrinsic, Err);
    ob_video_stream_profile_set_distortion: fn(*mut ObStreamProfile, ObCameraDistortion, Err);
    ob_stream_profile_set_extrinsic_to:
        fn(*mut ObStreamProfile, *const ObStreamProfile, ObExtrinsic, Err);
    ob_create_video_frame: fn(c_int, c_int, u32, u32, u32, Err) -> *mut ObFrame;
    ob_frame_set_stream_profile: fn(*mut ObFrame, *const ObStreamProfile, Err);
    ob_frame_update_data: fn(*mut ObFrame, *const u8, u32, Err);
    ob_frame_set_timestamp_us: fn(*mut ObFrame, u64, Err);
    ob_frame_set_system_timestamp_us: fn(*mut ObFrame, u64, Err);
    ob_depth_frame_set_value_scale: fn(*mut ObFrame, f32, Err);
    ob_create_frameset: fn(Err) -> *mut ObFrame;
    ob_frameset_push_frame: fn(*mut ObFrame, *const ObFrame, Err);
}

/// An error the SDK reported through `ob_error`, copied out and freed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SdkError {
    /// The SDK function that was called (ours, not the SDK's internal one).
    pub call: &'static str,
    pub status: i32,
    pub exception: i32,
    pub message: String,
    pub function: String,
}

impl std::fmt::Display for SdkError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} failed: {} (status {}, exception type {}",
            self.call, self.message, self.status, self.exception
        )?;
        if !self.function.is_empty() {
            write!(f, ", in {}", self.function)?;
        }
        f.write_str(")")
    }
}

fn cstr_to_string(p: *const c_char) -> String {
    if p.is_null() {
        return String::new();
    }
    // SAFETY: non-null strings from the SDK are NUL-terminated and live at least as long as the
    // object they were read from, which the caller still holds; we copy before returning.
    unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
}

/// The loaded SDK.
pub struct Sdk {
    api: Api,
}

impl Sdk {
    /// Load the library at `path` and resolve every function the driver uses.
    pub fn load(path: &Path) -> Result<Arc<Sdk>, String> {
        let api = Api::load(path)?;
        Ok(Arc::new(Sdk { api }))
    }

    /// Call `f` with an `ob_error**` out-parameter; turn a set error into `SdkError`.
    fn call<T>(&self, call: &'static str, f: impl FnOnce(Err) -> T) -> Result<T, SdkError> {
        let mut err: *mut ObError = ptr::null_mut();
        let out = f(&mut err);
        if err.is_null() {
            return Ok(out);
        }
        // SAFETY: `err` was set by the SDK to a valid ob_error that we own; it is read and then
        // deleted exactly once here.
        let e = unsafe {
            SdkError {
                call,
                status: (self.api.ob_error_get_status)(err),
                exception: (self.api.ob_error_get_exception_type)(err),
                message: cstr_to_string((self.api.ob_error_get_message)(err)),
                function: cstr_to_string((self.api.ob_error_get_function)(err)),
            }
        };
        // SAFETY: see above; `err` is not used afterwards.
        unsafe { (self.api.ob_delete_error)(err) };
        Err(e)
    }

    /// The SDK's version, e.g. (2, 9, 3).
    pub fn version(&self) -> (i32, i32, i32) {
        // SAFETY: argument-less getters of constants.
        unsafe {
            (
                (self.api.ob_get_major_version)(),
                (self.api.ob_get_minor_version)(),
                (self.api.ob_get_patch_version)(),
            )
        }
    }

    /// No log files in the working directory; warnings and errors to the console.
    pub fn quiet_logs(&self) -> Result<(), SdkError> {
        let empty = CString::default();
        // SAFETY: `empty` is a valid C string that outlives the call; severity is a valid enumerator.
        self.call("ob_set_logger_to_file", |e| unsafe {
            (self.api.ob_set_logger_to_file)(OB_LOG_SEVERITY_OFF, empty.as_ptr(), e)
        })?;
        // SAFETY: valid enumerator and error out-pointer.
        self.call("ob_set_logger_to_console", |e| unsafe {
            (self.api.ob_set_logger_to_console)(OB_LOG_SEVERITY_WARN, e)
        })
    }
}

/// Null from a constructor without an `ob_error` is still a failure.
fn non_null<T>(p: *mut T, call: &'static str) -> Result<*mut T, SdkError> {
    if p.is_null() {
        Err(SdkError {
            call,
            status: -1,
            exception: 0,
            message: "returned NULL".into(),
            function: String::new(),
        })
    } else {
        Ok(p)
    }
}

/// An `ob_context`.
pub struct Context {
    sdk: Arc<Sdk>,
    ptr: *mut ObContext,
}

impl Context {
    pub fn new(sdk: &Arc<Sdk>) -> Result<Context, SdkError> {
        // SAFETY: plain constructor; the result is checked for NULL and owned by `Context`.
        let p = sdk.call("ob_create_context", |e| unsafe { (sdk.api.ob_create_context)(e) })?;
        Ok(Context { sdk: Arc::clone(sdk), ptr: non_null(p, "ob_create_context")? })
    }

    /// Put frame system timestamps on CLOCK_MONOTONIC (the clock of `std::time::Instant`).
    pub fn use_monotonic_timestamps(&self) -> Result<(), SdkError> {
        let api = &self.sdk.api;
        // SAFETY: `self.ptr` is a live context; the clock type is a valid enumerator.
        self.sdk.call("ob_context_set_timestamp_clock_type", |e| unsafe {
            (api.ob_context_set_timestamp_clock_type)(self.ptr, OB_CLOCK_TYPE_MONOTONIC, e)
        })
    }

    pub fn devices(&self) -> Result<DeviceList, SdkError> {
        let api = &self.sdk.api;
        // SAFETY: `self.ptr` is a live context; the returned list is owned by `DeviceList`.
        let p = self
            .sdk
            .call("ob_query_device_list", |e| unsafe { (api.ob_query_device_list)(self.ptr, e) })?;
        Ok(DeviceList { sdk: Arc::clone(&self.sdk), ptr: non_null(p, "ob_query_device_list")? })
    }
}

impl Drop for Context {
    fn drop(&mut self) {
        // SAFETY: `ptr` is live and deleted once; every object made from it holds its own
        // reference in the SDK, and ours are dropped first (field order of the owners).
        let _ = self.sdk.call("ob_delete_context", |e| unsafe {
            (self.sdk.api.ob_delete_context)(self.ptr, e)
        });
    }
}

/// An `ob_device_list`.
pub struct DeviceList {
    sdk: Arc<Sdk>,
    ptr: *mut ObDeviceList,
}

impl DeviceList {
    pub fn count(&self) -> Result<u32, SdkError> {
        // SAFETY: `self.ptr` is a live device list.
        self.sdk.call("ob_device_list_get_count", |e| unsafe {
            (self.sdk.api.ob_device_list_get_count)(self.ptr, e)
        })
    }

    /// The serial number of camera `index`, read from the list without opening the camera.
    pub fn serial(&self, index: u32) -> Result<String, SdkError> {
        // SAFETY: `self.ptr` is live; the string belongs to the list, which outlives the copy.
        self.sdk.call("ob_device_list_get_device_serial_number", |e| {
            cstr_to_string(unsafe {
                (self.sdk.api.ob_device_list_get_device_serial_number)(self.ptr, index, e)
            })
        })
    }

    pub fn device(&self, index: u32) -> Result<Device, SdkError> {
        // SAFETY: `self.ptr` is live; an out-of-range index is reported through `ob_error`.
        let p = self.sdk.call("ob_device_list_get_device", |e| unsafe {
            (self.sdk.api.ob_device_list_get_device)(self.ptr, index, e)
        })?;
        Ok(Device { sdk: Arc::clone(&self.sdk), ptr: non_null(p, "ob_device_list_get_device")? })
    }
}

impl Drop for DeviceList {
    fn drop(&mut self) {
        // SAFETY: live and deleted once.
        let _ = self.sdk.call("ob_delete_device_list", |e| unsafe {
            (self.sdk.api.ob_delete_device_list)(self.ptr, e)
        });
    }
}

/// What a device says about itself (copied out of `ob_device_info`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeviceIdentity {
    pub name: String,
    pub serial: String,
    pub pid: c_int,
    pub firmware: String,
}

/// One entry of a stream profile list: size, `ob_format` and frame rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProfileDesc {
    pub width: u32,
    pub height: u32,
    pub format: c_int,
    pub fps: u32,
}

/// An opened `ob_device`.
pub struct Device {
    sdk: Arc<Sdk>,
    ptr: *mut ObDevice,
}

impl Device {
    /// Name, serial number, USB product id and firmware version.
    pub fn describe(&self) -> Result<DeviceIdentity, SdkError> {
        let api = &self.sdk.api;
        // SAFETY: `self.ptr` is a live device; the info object is deleted below.
        let info = self.sdk.call("ob_device_get_device_info", |e| unsafe {
            (api.ob_device_get_device_info)(self.ptr, e)
        })?;
        let info = non_null(info, "ob_device_get_device_info")?;
        // SAFETY: `info` is live until deleted below; the strings are copied before that.
        let name = self.sdk.call("ob_device_info_get_name", |e| {
            cstr_to_string(unsafe { (api.ob_device_info_get_name)(info, e) })
        });
        // SAFETY: as above.
        let serial = self.sdk.call("ob_device_info_get_serial_number", |e| {
            cstr_to_string(unsafe { (api.ob_device_info_get_serial_number)(info, e) })
        });
        // SAFETY: as above.
        let firmware = self.sdk.call("ob_device_info_get_firmware_version", |e| {
            cstr_to_string(unsafe { (api.ob_device_info_get_firmware_version)(info, e) })
        });
        // SAFETY: as above (a plain integer getter).
        let pid = self
            .sdk
            .call("ob_device_info_get_pid", |e| unsafe { (api.ob_device_info_get_pid)(info, e) });
        // SAFETY: deleted once, not used afterwards.
        let _ = self
            .sdk
            .call("ob_delete_device_info", |e| unsafe { (api.ob_delete_device_info)(info, e) });
        Ok(DeviceIdentity { name: name?, serial: serial?, pid: pid?, firmware: firmware? })
    }

    /// Whether the device lets us write integer property `id`.
    pub fn property_writable(&self, id: c_int) -> Result<bool, SdkError> {
        // SAFETY: `self.ptr` is a live device; `id` and the permission are plain integers.
        self.sdk.call("ob_device_is_property_supported", |e| unsafe {
            (self.sdk.api.ob_device_is_property_supported)(self.ptr, id, OB_PERMISSION_WRITE, e)
        })
    }

    /// Whether the device lets us read integer property `id`.
    pub fn property_readable(&self, id: c_int) -> Result<bool, SdkError> {
        // SAFETY: `self.ptr` is a live device; `id` and the permission are plain integers.
        self.sdk.call("ob_device_is_property_supported", |e| unsafe {
            (self.sdk.api.ob_device_is_property_supported)(self.ptr, id, OB_PERMISSION_READ, e)
        })
    }

    pub fn int_property(&self, id: c_int) -> Result<i32, SdkError> {
        // SAFETY: `self.ptr` is a live device; an unknown id is reported via `ob_error`.
        self.sdk.call("ob_device_get_int_property", |e| unsafe {
            (self.sdk.api.ob_device_get_int_property)(self.ptr, id, e)
        })
    }

    pub fn set_int_property(&self, id: c_int, value: i32) -> Result<(), SdkError> {
        // SAFETY: `self.ptr` is a live device; an unknown id or value is reported via `ob_error`.
        self.sdk.call("ob_device_set_int_property", |e| unsafe {
            (self.sdk.api.ob_device_set_int_property)(self.ptr, id, value, e)
        })
    }

    pub fn sync_modes(&self) -> Result<u16, SdkError> {
        // SAFETY: `self.ptr` is a live device.
        self.sdk.call("ob_device_get_supported_multi_device_sync_mode_bitmap", |e| unsafe {
            (self.sdk.api.ob_device_get_supported_multi_device_sync_mode_bitmap)(self.ptr, e)
        })
    }

    pub fn sync_config(&self) -> Result<ObMultiDeviceSyncConfig, SdkError> {
        // SAFETY: `self.ptr` is a live device; the struct is returned by value.
        self.sdk.call("ob_device_get_multi_device_sync_config", |e| unsafe {
            (self.sdk.api.ob_device_get_multi_device_sync_config)(self.ptr, e)
        })
    }

    pub fn set_sync_config(&self, config: &ObMultiDeviceSyncConfig) -> Result<(), SdkError> {
        // SAFETY: `self.ptr` is a live device; `config` points to a valid struct for the call.
        self.sdk.call("ob_device_set_multi_device_sync_config", |e| unsafe {
            (self.sdk.api.ob_device_set_multi_device_sync_config)(self.ptr, config, e)
        })
    }

    /// Turn on global timestamps (device exposure time converted to the host clock) where the
    /// camera supports them; returns whether they are on.
    pub fn enable_global_timestamps(&self) -> Result<bool, SdkError> {
        let api = &self.sdk.api;
        // SAFETY: `self.ptr` is a live device.
        let supported = self.sdk.call("ob_device_is_global_timestamp_supported", |e| unsafe {
            (api.ob_device_is_global_timestamp_supported)(self.ptr, e)
        })?;
        if supported {
            // SAFETY: `self.ptr` is a live device.
            self.sdk.call("ob_device_enable_global_timestamp", |e| unsafe {
                (api.ob_device_enable_global_timestamp)(self.ptr, true, e)
            })?;
        }
        Ok(supported)
    }

    pub fn trigger_capture(&self) -> Result<(), SdkError> {
        // SAFETY: `self.ptr` is a live device.
        self.sdk.call("ob_device_trigger_capture", |e| unsafe {
            (self.sdk.api.ob_device_trigger_capture)(self.ptr, e)
        })
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        // SAFETY: live and deleted once.
        let _ = self
            .sdk
            .call("ob_delete_device", |e| unsafe { (self.sdk.api.ob_delete_device)(self.ptr, e) });
    }
}

/// A video stream profile found for the pipeline.
pub struct Profile {
    sdk: Arc<Sdk>,
    ptr: *mut ObStreamProfile,
}

impl Profile {
    pub fn intrinsic(&self) -> Result<ObCameraIntrinsic, SdkError> {
        // SAFETY: `self.ptr` is a live video stream profile.
        self.sdk.call("ob_video_stream_profile_get_intrinsic", |e| unsafe {
            (self.sdk.api.ob_video_stream_profile_get_intrinsic)(self.ptr, e)
        })
    }

    /// The lens distortion the SDK reports for this profile.
    pub fn distortion(&self) -> Result<ObCameraDistortion, SdkError> {
        // SAFETY: `self.ptr` is a live video stream profile; the struct is returned by value.
        self.sdk.call("ob_video_stream_profile_get_distortion", |e| unsafe {
            (self.sdk.api.ob_video_stream_profile_get_distortion)(self.ptr, e)
        })
    }

    pub fn size(&self) -> Result<(u32, u32), SdkError> {
        let api = &self.sdk.api;
        // SAFETY: `self.ptr` is a live video stream profile.
        let w = self.sdk.call("ob_video_stream_profile_get_width", |e| unsafe {
            (api.ob_video_stream_profile_get_width)(self.ptr, e)
        })?;
        // SAFETY: as above.
        let h = self.sdk.call("ob_video_stream_profile_get_height", |e| unsafe {
            (api.ob_video_stream_profile_get_height)(self.ptr, e)
        })?;
        Ok((w, h))
    }
}

impl Profile {
    /// Size, format and frame rate of a video profile.
    pub fn desc(&self) -> Result<ProfileDesc, SdkError> {
        let api = &self.sdk.api;
        let (width, height) = self.size()?;
        // SAFETY: `self.ptr` is a live video stream profile.
        let format = self.sdk.call("ob_stream_profile_get_format", |e| unsafe {
            (api.ob_stream_profile_get_format)(self.ptr, e)
        })?;
        // SAFETY: as above.
        let fps = self.sdk.call("ob_video_stream_profile_get_fps", |e| unsafe {
            (api.ob_video_stream_profile_get_fps)(self.ptr, e)
        })?;
        Ok(ProfileDesc { width, height, format, fps })
    }

    /// A free-standing video profile (for frames built without a camera).
    #[cfg(test)]
    pub fn new_video(
        sdk: &Arc<Sdk>,
        stream: c_int,
        d: ProfileDesc,
        k: ObCameraIntrinsic,
    ) -> Result<Profile, SdkError> {
        let api = &sdk.api;
        // SAFETY: plain constructor with valid enumerators; owned by `Profile`.
        let p = sdk.call("ob_create_video_stream_profile", |e| unsafe {
            (api.ob_create_video_stream_profile)(stream, d.format, d.width, d.height, d.fps, e)
        })?;
        let profile =
            Profile { sdk: Arc::clone(sdk), ptr: non_null(p, "ob_create_video_stream_profile")? };
        // SAFETY: `profile.ptr` is live; the struct is passed by value.
        sdk.call("ob_video_stream_profile_set_intrinsic", |e| unsafe {
            (api.ob_video_stream_profile_set_intrinsic)(profile.ptr, k, e)
        })?;
        let none = ObCameraDistortion { model: OB_DISTORTION_NONE, ..Default::default() };
        // SAFETY: as above.
        sdk.call("ob_video_stream_profile_set_distortion", |e| unsafe {
            (api.ob_video_stream_profile_set_distortion)(profile.ptr, none, e)
        })?;
        Ok(profile)
    }

    /// Record the extrinsic from this profile's stream to `target`'s.
    #[cfg(test)]
    pub fn set_extrinsic_to(&self, target: &Profile, x: ObExtrinsic) -> Result<(), SdkError> {
        // SAFETY: both profiles are live; the struct is passed by value.
        self.sdk.call("ob_stream_profile_set_extrinsic_to", |e| unsafe {
            (self.sdk.api.ob_stream_profile_set_extrinsic_to)(self.ptr, target.ptr, x, e)
        })
    }
}

impl Drop for Profile {
    fn drop(&mut self) {
        // SAFETY: live and deleted once.
        let _ = self.sdk.call("ob_delete_stream_profile", |e| unsafe {
            (self.sdk.api.ob_delete_stream_profile)(self.ptr, e)
        });
    }
}

/// An `ob_pipeline` on one device, with the config it was started with.
pub struct Pipeline {
    sdk: Arc<Sdk>,
    ptr: *mut ObPipeline,
    started: bool,
}

impl Pipeline {
    pub fn new(device: &Device) -> Result<Pipeline, SdkError> {
        let sdk = &device.sdk;
        // SAFETY: `device.ptr` is a live device; the pipeline takes its own reference to it.
        let p = sdk.call("ob_create_pipeline_with_device", |e| unsafe {
            (sdk.api.ob_create_pipeline_with_device)(device.ptr, e)
        })?;
        Ok(Pipeline {
            sdk: Arc::clone(sdk),
            ptr: non_null(p, "ob_create_pipeline_with_device")?,
            started: false,
        })
    }

    /// Every profile the pipeline offers for `sensor` (video profiles only).
    pub fn profiles(&self, sensor: c_int) -> Result<Vec<ProfileDesc>, SdkError> {
        let api = &self.sdk.api;
        // SAFETY: `self.ptr` is a live pipeline; the list is deleted below.
        let list = self.sdk.call("ob_pipeline_get_stream_profile_list", |e| unsafe {
            (api.ob_pipeline_get_stream_profile_list)(self.ptr, sensor, e)
        })?;
        let list = non_null(list, "ob_pipeline_get_stream_profile_list")?;
        let result = (|| {
            // SAFETY: `list` is live.
            let n = self.sdk.call("ob_stream_profile_list_get_count", |e| unsafe {
                (api.ob_stream_profile_list_get_count)(list, e)
            })?;
            let mut out = Vec::new();
            for i in 0..n.min(4096) {
                let i = c_int::try_from(i).unwrap_or(c_int::MAX);
                // SAFETY: `list` is live and `i` is below its count; the profile is owned below.
                let p = self.sdk.call("ob_stream_profile_list_get_profile", |e| unsafe {
                    (api.ob_stream_profile_list_get_profile)(list, i, e)
                })?;
                let p = Profile {
                    sdk: Arc::clone(&self.sdk),
                    ptr: non_null(p, "ob_stream_profile_list_get_profile")?,
                };
                out.push(p.desc()?);
            }
            Ok(out)
        })();
        // SAFETY: deleted once; profiles taken from it hold their own references.
        let _ = self.sdk.call("ob_delete_stream_profile_list", |e| unsafe {
            (api.ob_delete_stream_profile_list)(list, e)
        });
        result
    }

    /// The video profile of `sensor` with exactly this size, format and frame rate.
    pub fn video_profile(&self, sensor: c_int, want: ProfileDesc) -> Result<Profile, SdkError> {
        let api = &self.sdk.api;
        // SAFETY: `self.ptr` is a live pipeline; the list is deleted below.
        let list = self.sdk.call("ob_pipeline_get_stream_profile_list", |e| unsafe {
            (api.ob_pipeline_get_stream_profile_list)(self.ptr, sensor, e)
        })?;
        let list = non_null(list, "ob_pipeline_get_stream_profile_list")?;
        let w = c_int::try_from(want.width).unwrap_or(c_int::MAX);
        let h = c_int::try_from(want.height).unwrap_or(c_int::MAX);
        let fps = c_int::try_from(want.fps).unwrap_or(c_int::MAX);
        // SAFETY: `list` is live; the returned profile is owned by `Profile`.
        let profile =
            self.sdk.call("ob_stream_profile_list_get_video_stream_profile", |e| unsafe {
                (api.ob_stream_profile_list_get_video_stream_profile)(
                    list,
                    w,
                    h,
                    want.format,
                    fps,
                    e,
                )
            });
        // SAFETY: deleted once; the profile holds its own reference.
        let _ = self.sdk.call("ob_delete_stream_profile_list", |e| unsafe {
            (api.ob_delete_stream_profile_list)(list, e)
        });
        let p = non_null(profile?, "ob_stream_profile_list_get_video_stream_profile")?;
        Ok(Profile { sdk: Arc::clone(&self.sdk), ptr: p })
    }

    /// Start colour + depth, both frames required in every frameset. (No pipeline align mode:
    /// 2.9.3 ignores the software one; depth is aligned by [`AlignFilter`].)
    pub fn start(&mut self, color: &Profile, depth: &Profile) -> Result<(), SdkError> {
        let api = &self.sdk.api;
        // SAFETY: plain constructor; deleted below.
        let config = self.sdk.call("ob_create_config", |e| unsafe { (api.ob_create_config)(e) })?;
        let config = non_null(config, "ob_create_config")?;
        let result = (|| {
            // SAFETY: `config` and the profiles are live for these calls.
            self.sdk.call("ob_config_enable_stream_with_stream_profile", |e| unsafe {
                (api.ob_config_enable_stream_with_stream_profile)(config, color.ptr, e)
            })?;
            // SAFETY: as above.
            self.sdk.call("ob_config_enable_stream_with_stream_profile", |e| unsafe {
                (api.ob_config_enable_stream_with_stream_profile)(config, depth.ptr, e)
            })?;
            // SAFETY: `config` live, valid enumerator.
            self.sdk.call("ob_config_set_frame_aggregate_output_mode", |e| unsafe {
                (api.ob_config_set_frame_aggregate_output_mode)(
                    config,
                    OB_FRAME_AGGREGATE_OUTPUT_ALL_TYPE_FRAME_REQUIRE,
                    e,
                )
            })?;
            // SAFETY: pipeline and config are live; the pipeline copies the config.
            self.sdk.call("ob_pipeline_start_with_config", |e| unsafe {
                (api.ob_pipeline_start_with_config)(self.ptr, config, e)
            })
        })();
        // SAFETY: deleted once after its last use.
        let _ = self.sdk.call("ob_delete_config", |e| unsafe { (api.ob_delete_config)(config, e) });
        result?;
        self.started = true;
        Ok(())
    }

    /// Stop the streams (nothing when they are not running).
    pub fn stop(&mut self) -> Result<(), SdkError> {
        if !self.started {
            return Ok(());
        }
        self.started = false;
        // SAFETY: `self.ptr` is a live, started pipeline.
        self.sdk
            .call("ob_pipeline_stop", |e| unsafe { (self.sdk.api.ob_pipeline_stop)(self.ptr, e) })
    }

    /// Wait up to `timeout_ms` for a frameset; `None` on timeout.
    pub fn wait_frameset(&mut self, timeout_ms: u32) -> Result<Option<Frame>, SdkError> {
        // SAFETY: `self.ptr` is a live pipeline; a returned frameset is owned by `Frame`.
        let p = self.sdk.call("ob_pipeline_wait_for_frameset", |e| unsafe {
            (self.sdk.api.ob_pipeline_wait_for_frameset)(self.ptr, timeout_ms, e)
        })?;
        Ok((!p.is_null()).then(|| Frame { sdk: Arc::clone(&self.sdk), ptr: p }))
    }
}

impl Drop for Pipeline {
    fn drop(&mut self) {
        if self.started {
            // SAFETY: live pipeline.
            let _ = self.sdk.call("ob_pipeline_stop", |e| unsafe {
                (self.sdk.api.ob_pipeline_stop)(self.ptr, e)
            });
        }
        // SAFETY: live and deleted once.
        let _ = self.sdk.call("ob_delete_pipeline", |e| unsafe {
            (self.sdk.api.ob_delete_pipeline)(self.ptr, e)
        });
    }
}

/// A frame or frameset.
pub struct Frame {
    sdk: Arc<Sdk>,
    ptr: *mut ObFrame,
}

impl Frame {
    fn sub(
        &self,
        call: &'static str,
        f: unsafe extern "C" fn(*const ObFrame, Err) -> *mut ObFrame,
    ) -> Result<Option<Frame>, SdkError> {
        // SAFETY: `self.ptr` is a live frameset; a returned frame is a new reference owned by `Frame`.
        let p = self.sdk.call(call, |e| unsafe { f(self.ptr, e) })?;
        Ok((!p.is_null()).then(|| Frame { sdk: Arc::clone(&self.sdk), ptr: p }))
    }

    pub fn color(&self) -> Result<Option<Frame>, SdkError> {
        self.sub("ob_frameset_get_color_frame", self.sdk.api.ob_frameset_get_color_frame)
    }

    pub fn depth(&self) -> Result<Option<Frame>, SdkError> {
        self.sub("ob_frameset_get_depth_frame", self.sdk.api.ob_frameset_get_depth_frame)
    }

    pub fn format(&self) -> Result<c_int, SdkError> {
        // SAFETY: live frame.
        self.sdk.call("ob_frame_get_format", |e| unsafe {
            (self.sdk.api.ob_frame_get_format)(self.ptr, e)
        })
    }

    pub fn size(&self) -> Result<(u32, u32), SdkError> {
        let api = &self.sdk.api;
        // SAFETY: live video frame.
        let w = self.sdk.call("ob_video_frame_get_width", |e| unsafe {
            (api.ob_video_frame_get_width)(self.ptr, e)
        })?;
        // SAFETY: live video frame.
        let h = self.sdk.call("ob_video_frame_get_height", |e| unsafe {
            (api.ob_video_frame_get_height)(self.ptr, e)
        })?;
        Ok((w, h))
    }

    /// Device, host-arrival (system) and global (exposure on the host clock, 0 when off)
    /// timestamps, microseconds.
    pub fn timestamps_us(&self) -> Result<(u64, u64, u64), SdkError> {
        let api = &self.sdk.api;
        // SAFETY: live frame.
        let dev = self.sdk.call("ob_frame_get_timestamp_us", |e| unsafe {
            (api.ob_frame_get_timestamp_us)(self.ptr, e)
        })?;
        // SAFETY: live frame.
        let sys = self.sdk.call("ob_frame_get_system_timestamp_us", |e| unsafe {
            (api.ob_frame_get_system_timestamp_us)(self.ptr, e)
        })?;
        // SAFETY: live frame.
        let global = self.sdk.call("ob_frame_get_global_timestamp_us", |e| unsafe {
            (api.ob_frame_get_global_timestamp_us)(self.ptr, e)
        })?;
        Ok((dev, sys, global))
    }

    /// Millimetres per depth unit.
    pub fn depth_scale_mm(&self) -> Result<f32, SdkError> {
        // SAFETY: live depth frame.
        self.sdk.call("ob_depth_frame_get_value_scale", |e| unsafe {
            (self.sdk.api.ob_depth_frame_get_value_scale)(self.ptr, e)
        })
    }

    /// A new video frame of `frame_type` with its profile, data, timestamps and (for depth)
    /// value scale set: how the tests make frames the real library then processes.
    #[cfg(test)]
    pub fn new_video(
        profile: &Profile,
        frame_type: c_int,
        d: ProfileDesc,
        data: &[u8],
        device_us: u64,
        system_us: u64,
        depth_scale_mm: Option<f32>,
    ) -> Result<Frame, SdkError> {
        let sdk = &profile.sdk;
        let api = &sdk.api;
        // SAFETY: plain constructor; stride 0 = computed from width and format.
        let p = sdk.call("ob_create_video_frame", |e| unsafe {
            (api.ob_create_video_frame)(frame_type, d.format, d.width, d.height, 0, e)
        })?;
        let frame = Frame { sdk: Arc::clone(sdk), ptr: non_null(p, "ob_create_video_frame")? };
        let n = u32::try_from(data.len()).unwrap_or(u32::MAX);
        // SAFETY: frame and profile are live; `data` is valid for `n` bytes during the call
        // (the SDK copies it and checks `n` against the frame's size).
        sdk.call("ob_frame_set_stream_profile", |e| unsafe {
            (api.ob_frame_set_stream_profile)(frame.ptr, profile.ptr, e)
        })?;
        // SAFETY: as above.
        sdk.call("ob_frame_update_data", |e| unsafe {
            (api.ob_frame_update_data)(frame.ptr, data.as_ptr(), n, e)
        })?;
        // SAFETY: live frame.
        sdk.call("ob_frame_set_timestamp_us", |e| unsafe {
            (api.ob_frame_set_timestamp_us)(frame.ptr, device_us, e)
        })?;
        // SAFETY: live frame.
        sdk.call("ob_frame_set_system_timestamp_us", |e| unsafe {
            (api.ob_frame_set_system_timestamp_us)(frame.ptr, system_us, e)
        })?;
        if let Some(scale) = depth_scale_mm {
            // SAFETY: live depth frame.
            sdk.call("ob_depth_frame_set_value_scale", |e| unsafe {
                (api.ob_depth_frame_set_value_scale)(frame.ptr, scale, e)
            })?;
        }
        Ok(frame)
    }

    /// A frameset holding `frames` (each gains a reference held by the set).
    #[cfg(test)]
    pub fn new_frameset(sdk: &Arc<Sdk>, frames: &[&Frame]) -> Result<Frame, SdkError> {
        let api = &sdk.api;
        // SAFETY: plain constructor, owned by `Frame`.
        let p = sdk.call("ob_create_frameset", |e| unsafe { (api.ob_create_frameset)(e) })?;
        let set = Frame { sdk: Arc::clone(sdk), ptr: non_null(p, "ob_create_frameset")? };
        for f in frames {
            // SAFETY: both are live frames; the set takes its own reference to `f`.
            sdk.call("ob_frameset_push_frame", |e| unsafe {
                (api.ob_frameset_push_frame)(set.ptr, f.ptr, e)
            })?;
        }
        Ok(set)
    }

    /// The frame's bytes (valid while the frame is).
    pub fn data(&self) -> Result<&[u8], SdkError> {
        let api = &self.sdk.api;
        // SAFETY: live frame.
        let p = self
            .sdk
            .call("ob_frame_get_data", |e| unsafe { (api.ob_frame_get_data)(self.ptr, e) })?;
        // SAFETY: live frame.
        let n = self.sdk.call("ob_frame_get_data_size", |e| unsafe {
            (api.ob_frame_get_data_size)(self.ptr, e)
        })?;
        if p.is_null() || n == 0 {
            return Ok(&[]);
        }
        // SAFETY: the SDK guarantees `n` readable bytes at `p` until the frame is deleted, which
        // cannot happen while `&self` is borrowed; nothing writes the buffer meanwhile.
        Ok(unsafe { std::slice::from_raw_parts(p, n as usize) })
    }
}

/// The SDK's `Align` filter, set to align depth to the colour stream (D2C in software), into
/// the colour image as the lens distorts it.
pub struct AlignFilter {
    sdk: Arc<Sdk>,
    ptr: *mut ObFilter,
}

impl AlignFilter {
    /// `into_distorted`: register into the colour image as its lens distorts it (a colour
    /// stream with a distortion); false for a pinhole colour stream, where it changes nothing.
    pub fn depth_to_color(sdk: &Arc<Sdk>, into_distorted: bool) -> Result<AlignFilter, SdkError> {
        let api = &sdk.api;
        let name = c"Align";
        // SAFETY: `name` is a valid C string for the call; the filter is owned by `AlignFilter`.
        let p =
            sdk.call("ob_create_filter", |e| unsafe { (api.ob_create_filter)(name.as_ptr(), e) })?;
        let filter = AlignFilter { sdk: Arc::clone(sdk), ptr: non_null(p, "ob_create_filter")? };
        let key = c"AlignType";
        // SAFETY: live filter; `key` is a valid C string; OB_STREAM_COLOR is in the schema's range.
        sdk.call("ob_filter_set_config_value", |e| unsafe {
            (api.ob_filter_set_config_value)(
                filter.ptr,
                key.as_ptr(),
                f64::from(OB_STREAM_COLOR),
                e,
            )
        })?;
        // Register depth into the *distorted* colour image (the SDK's default projects it into
        // undistorted colour coordinates while the colour image stays distorted): depth and
        // colour then agree pixel for pixel, and both carry the colour lens's distortion.
        if into_distorted {
            let key = c"TargetDistortion";
            // SAFETY: live filter; `key` is a valid C string; 1 is in the boolean's range.
            sdk.call("ob_filter_set_config_value", |e| unsafe {
                (api.ob_filter_set_config_value)(filter.ptr, key.as_ptr(), 1.0, e)
            })?;
        }
        Ok(filter)
    }

    /// The frameset with its depth replaced by depth aligned to the colour frame; `None` when
    /// the filter gives nothing back (it logs why).
    pub fn process(&mut self, frameset: &Frame) -> Result<Option<Frame>, SdkError> {
        // SAFETY: filter and frameset are live; a returned frame is a new reference we own.
        let p = self.sdk.call("ob_filter_process", |e| unsafe {
            (self.sdk.api.ob_filter_process)(self.ptr, frameset.ptr, e)
        })?;
        Ok((!p.is_null()).then(|| Frame { sdk: Arc::clone(&self.sdk), ptr: p }))
    }
}

impl Drop for AlignFilter {
    fn drop(&mut self) {
        // SAFETY: live and deleted once.
        let _ = self
            .sdk
            .call("ob_delete_filter", |e| unsafe { (self.sdk.api.ob_delete_filter)(self.ptr, e) });
    }
}

impl Drop for Frame {
    fn drop(&mut self) {
        // SAFETY: live and released once (frames are reference-counted by the SDK).
        let _ = self
            .sdk
            .call("ob_delete_frame", |e| unsafe { (self.sdk.api.ob_delete_frame)(self.ptr, e) });
    }
}
