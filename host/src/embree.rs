//! A small safe wrapper over Embree 4 (`embree4-sys`): a device, a committed triangle scene, occlusion and
//! closest-hit queries.
//!
//! This module holds all of `radiosity-host`'s `unsafe` code. Every `unsafe` block states why it is sound.
//!
//! # Use
//! ```no_run
//! use glam::Vec3;
//! use radiosity_host::embree::{Device, Ray, SceneOptions};
//!
//! let device = Device::new()?;
//! let vertices = [Vec3::ZERO, Vec3::X, Vec3::Y];
//! let scene = device.triangle_scene(&vertices, &[[0, 1, 2]], SceneOptions::default())?;
//! let ray = Ray::segment(Vec3::new(0.2, 0.2, 1.0), Vec3::new(0.2, 0.2, -1.0), scene.offset());
//! assert!(scene.occluded(&ray));
//! # Ok::<(), radiosity_host::embree::EmbreeError>(())
//! ```
//!
//! # Embree's ray conventions, and how this module handles them
//! - A ray covers the points `origin + t * direction` for `tnear < t <= tfar` (Embree's triangle tests compare
//!   `tnear < t` and `t <= tfar`): a segment that ends exactly on a surface hits it. [`Ray::segment`] therefore
//!   pulls both ends in by an absolute offset (see [`TriangleScene::offset`]), so a segment from a point on one
//!   surface to a point on another is tested only between the two surfaces.
//! - `tnear` must be `>= 0`; a ray that starts on a surface with `tnear = 0` may hit that surface at `t ~ 0`
//!   through rounding. The same offset keeps it off its own surface.
//! - Triangles are two-sided (Embree is built without back-face culling); hits on edges count; degenerate
//!   triangles are never hit.
//! - The ray `mask` is set to all ones (`0xFFFF_FFFF`); Embree skips geometry whose mask does not intersect it.
//! - Occlusion queries report a blocked ray by setting its `tfar` to `-inf`; this module turns that into `bool`s.
//! - Embree works in `f32`; callers in `f64` convert at the boundary.
//! - Embree's triangle tests multiply up to three coordinates and its traversal flushes denormals to zero, so
//!   scenes far from unit size lose hits (at 1e12 the products overflow `f32`, at 1e-15 they flush to zero).
//!   [`TriangleScene`] therefore hands Embree the scene scaled by a power of two ([`unit_factor`]) that brings
//!   its size ([`crate::raycast::scene_scale`]) into `[1, 2)`, and scales every ray's origin and direction by the
//!   same factor. It also scales each ray's direction by a second power of two that brings the direction's length
//!   into `[1, 2)`, dividing `tnear` and `tfar` by it and multiplying a hit's `t` by it, so that a ray of any
//!   direction length (a unit direction as well as a segment's) reaches Embree well scaled. Multiplying by a
//!   power of two is exact in floating point, so callers keep working in their own units and `t`, and results do
//!   not depend on the scene's unit or on the direction's length.
//!
//! These are the semantics of [`crate::raycast`], whose [`Ray`] this module takes; [`TriangleScene`] is the
//! production [`RayCaster`], and [`crate::raycast::TriangleBvh`] the pure-Rust one it is tested against.
#![allow(unsafe_code)]

use std::ffi::{c_char, c_void, CStr, CString};
use std::fmt;
use std::sync::{Arc, Mutex};

use embree4_sys as sys;
use glam::Vec3;

use crate::raycast::{check_mesh, scene_scale, unit_factor, MeshInputError, RayCaster, RELATIVE_OFFSET};
pub use crate::raycast::{Hit, Ray};

/// An error reported by Embree, or bad input caught before it reaches Embree.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum EmbreeError {
    /// Embree reported an error code (named as in Embree's `RTCError`) with its message, during `operation`.
    #[error("Embree error {code} during {operation}: {message}")]
    Device {
        /// The Embree error code name, e.g. `RTC_ERROR_INVALID_ARGUMENT`.
        code: ErrorCode,
        /// What this module was doing when the error was reported.
        operation: &'static str,
        /// Embree's message, empty if it gave none.
        message: String,
    },
    /// The mesh is bad (a non-finite vertex, an index out of range), caught before Embree sees it.
    #[error(transparent)]
    Input(#[from] MeshInputError),
    /// The device configuration string contains a NUL byte.
    #[error("Embree device configuration contains a NUL byte at {0}")]
    ConfigNul(usize),
}

/// Embree's error codes (`RTCError`), named as in Embree's documentation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum ErrorCode {
    /// `RTC_ERROR_UNKNOWN`.
    Unknown,
    /// `RTC_ERROR_INVALID_ARGUMENT`.
    InvalidArgument,
    /// `RTC_ERROR_INVALID_OPERATION`.
    InvalidOperation,
    /// `RTC_ERROR_OUT_OF_MEMORY`.
    OutOfMemory,
    /// `RTC_ERROR_UNSUPPORTED_CPU`.
    UnsupportedCpu,
    /// `RTC_ERROR_CANCELLED`.
    Cancelled,
}

impl ErrorCode {
    /// Maps Embree's code; `None` for `RTC_ERROR_NONE`.
    fn from_raw(code: sys::RTCError) -> Option<Self> {
        match code {
            sys::RTCError::NONE => None,
            sys::RTCError::UNKNOWN => Some(Self::Unknown),
            sys::RTCError::INVALID_ARGUMENT => Some(Self::InvalidArgument),
            sys::RTCError::INVALID_OPERATION => Some(Self::InvalidOperation),
            sys::RTCError::OUT_OF_MEMORY => Some(Self::OutOfMemory),
            sys::RTCError::UNSUPPORTED_CPU => Some(Self::UnsupportedCpu),
            sys::RTCError::CANCELLED => Some(Self::Cancelled),
        }
    }

    /// The name Embree's documentation uses.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Unknown => "RTC_ERROR_UNKNOWN",
            Self::InvalidArgument => "RTC_ERROR_INVALID_ARGUMENT",
            Self::InvalidOperation => "RTC_ERROR_INVALID_OPERATION",
            Self::OutOfMemory => "RTC_ERROR_OUT_OF_MEMORY",
            Self::UnsupportedCpu => "RTC_ERROR_UNSUPPORTED_CPU",
            Self::Cancelled => "RTC_ERROR_CANCELLED",
        }
    }
}

impl fmt::Display for ErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

// Embree 4.3 and later export `rtcGetDeviceLastErrorMessage`, which `embree4-sys`'s bindings predate; the wheel
// `make deps` installs (4.4) has it. With a null device it returns the message of the failed `rtcNewDevice` on
// this thread: the only way to get Embree's own words when no device exists to carry an error callback.
extern "C" {
    fn rtcGetDeviceLastErrorMessage(device: sys::RTCDevice) -> *const c_char;
}

/// Embree's message for the last error of `rtcNewDevice` on this thread (empty if it gave none).
fn device_creation_message() -> String {
    // SAFETY: with a null device, Embree reads this thread's last device-creation error; the result is null or a
    // NUL-terminated string that Embree keeps valid until the next API call on this thread, and it is copied at
    // once.
    let message = unsafe { rtcGetDeviceLastErrorMessage(std::ptr::null_mut()) };
    if message.is_null() {
        return String::new();
    }
    // SAFETY: non-null, NUL-terminated (see above).
    unsafe { CStr::from_ptr(message) }.to_string_lossy().into_owned()
}

/// Where Embree's error callback leaves the first error it reports, until this module collects it.
#[derive(Default)]
struct ErrorSink {
    first: Mutex<Option<(sys::RTCError, String)>>,
}

/// Embree's error callback: records the first error and its message in the [`ErrorSink`] behind `user`.
///
/// Embree may call it from any thread that makes an API call on the device, hence the mutex.
unsafe extern "C" fn record_error(user: *mut c_void, code: sys::RTCError, message: *const c_char) {
    if user.is_null() {
        return;
    }
    // SAFETY: `user` is the pointer to the boxed `ErrorSink` that `Device::with_config` registered; the box lives in
    // `DeviceInner`, which outlives every object that can report an error on this device (scenes hold an `Arc` to it),
    // and it is only read through `&`.
    let sink = unsafe { &*user.cast::<ErrorSink>() };
    let text = if message.is_null() {
        String::new()
    } else {
        // SAFETY: Embree passes a NUL-terminated C string that is valid for the duration of the callback.
        unsafe { CStr::from_ptr(message) }.to_string_lossy().into_owned()
    };
    if let Ok(mut first) = sink.first.lock() {
        if first.is_none() {
            *first = Some((code, text));
        }
    }
}

struct DeviceInner {
    raw: sys::RTCDevice,
    // Boxed so its address, registered with Embree as the callback's user pointer, never moves.
    sink: Box<ErrorSink>,
}

// SAFETY: an `RTCDevice` is a reference-counted handle; Embree's API calls that take a device (creating scenes and
// geometries, querying errors) may be made from any thread, and the device's own state is internally synchronized.
// `ErrorSink` is `Sync` (a mutex). Nothing here is tied to the creating thread.
unsafe impl Send for DeviceInner {}
// SAFETY: see `Send`; shared access only creates objects or reads errors, which Embree allows concurrently.
unsafe impl Sync for DeviceInner {}

impl DeviceInner {
    /// Returns the pending error, if any, as an [`EmbreeError`] naming `operation`.
    fn check(&self, operation: &'static str) -> Result<(), EmbreeError> {
        // SAFETY: `self.raw` is a live device (released only in `Drop`); `rtcGetDeviceError` reads and clears the
        // device's error code.
        let code = unsafe { sys::rtcGetDeviceError(self.raw) };
        let recorded = self.sink.first.lock().ok().and_then(|mut first| first.take());
        let (code, message) = match (ErrorCode::from_raw(code), recorded) {
            (Some(code), Some((_, message))) => (code, message),
            (Some(code), None) => (code, String::new()),
            (None, Some((raw, message))) => (ErrorCode::from_raw(raw).unwrap_or(ErrorCode::Unknown), message),
            (None, None) => return Ok(()),
        };
        Err(EmbreeError::Device { code, operation, message })
    }
}

impl Drop for DeviceInner {
    fn drop(&mut self) {
        // SAFETY: `self.raw` came from `rtcNewDevice` and this is the only release of our reference. Every scene of
        // this device holds an `Arc<DeviceInner>` and releases its own handle first, so no object can still call the
        // error callback through `self.sink` after this point.
        unsafe { sys::rtcReleaseDevice(self.raw) };
    }
}

/// An Embree device: the context that owns scenes, with an error callback that turns Embree's errors into
/// [`EmbreeError`]s.
#[derive(Clone)]
pub struct Device {
    inner: Arc<DeviceInner>,
}

impl fmt::Debug for Device {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Device").finish_non_exhaustive()
    }
}

impl Device {
    /// Creates a device with Embree's default configuration.
    ///
    /// # Errors
    /// [`EmbreeError::Device`] if Embree cannot create a device (e.g. an unsupported CPU).
    pub fn new() -> Result<Self, EmbreeError> {
        Self::with_config("")
    }

    /// Creates a device with an Embree configuration string (e.g. `"threads=1"`; see `rtcNewDevice`).
    ///
    /// # Errors
    /// [`EmbreeError::ConfigNul`] if `config` holds a NUL byte; [`EmbreeError::Device`] if Embree rejects the
    /// configuration or cannot create a device.
    pub fn with_config(config: &str) -> Result<Self, EmbreeError> {
        let config = CString::new(config).map_err(|e| EmbreeError::ConfigNul(e.nul_position()))?;
        // SAFETY: `config` is a valid NUL-terminated string that outlives the call.
        let raw = unsafe { sys::rtcNewDevice(config.as_ptr()) };
        if raw.is_null() {
            // Embree's message first: reading the error code clears the thread's error.
            let embree = device_creation_message();
            // SAFETY: with a null device, `rtcGetDeviceError` returns the error of the failed `rtcNewDevice` on
            // this thread (documented behaviour of `rtcGetDeviceError`).
            let code = unsafe { sys::rtcGetDeviceError(std::ptr::null_mut()) };
            let embree = if embree.is_empty() { "no message".to_owned() } else { embree };
            return Err(EmbreeError::Device {
                code: ErrorCode::from_raw(code).unwrap_or(ErrorCode::Unknown),
                operation: "rtcNewDevice",
                message: format!(
                    "Embree could not create a device with configuration {:?}: {embree}",
                    config.to_string_lossy()
                ),
            });
        }
        let inner = DeviceInner { raw, sink: Box::default() };
        let user = std::ptr::from_ref::<ErrorSink>(&inner.sink).cast_mut().cast::<c_void>();
        // SAFETY: `raw` is a live device; `record_error` matches `RTCErrorFunction`; `user` points to the boxed
        // sink, which stays at this address until `inner` is dropped, after the device is released.
        unsafe { sys::rtcSetDeviceErrorFunction(raw, Some(record_error), user) };
        inner.check("rtcNewDevice")?;
        Ok(Self { inner: Arc::new(inner) })
    }

    /// Builds and commits a scene holding one triangle mesh (geometry id 0).
    ///
    /// Triangles refer to `vertices` by index. An empty mesh gives an empty scene in which nothing is occluded.
    /// Embree sees the vertices scaled by [`unit_factor`] (see the module docs); queries take and return
    /// values in the caller's units.
    ///
    /// # Errors
    /// [`EmbreeError::Input`] for bad input (checked before Embree
    /// sees it); [`EmbreeError::Device`] if Embree reports an error while building.
    pub fn triangle_scene(
        &self,
        vertices: &[Vec3],
        triangles: &[[u32; 3]],
        options: SceneOptions,
    ) -> Result<TriangleScene, EmbreeError> {
        check_mesh(vertices, triangles)?;
        let device = &self.inner;
        // SAFETY: `device.raw` is a live device.
        let raw = unsafe { sys::rtcNewScene(device.raw) };
        device.check("rtcNewScene")?;
        // From here on `scene` releases `raw` on every path, including errors.
        let scale = scene_scale(vertices);
        let scene = TriangleScene {
            raw,
            _device: Arc::clone(device),
            triangle_count: triangles.len(),
            scale,
            factor: unit_factor(scale),
        };
        let flags = if options.robust { sys::RTCSceneFlags::ROBUST } else { sys::RTCSceneFlags::NONE };
        // SAFETY: `raw` is a live, uncommitted scene owned by this thread; setting flags and build quality before
        // the commit is how Embree expects them to be set.
        unsafe {
            sys::rtcSetSceneFlags(raw, flags);
            sys::rtcSetSceneBuildQuality(raw, sys::RTCBuildQuality::HIGH);
        }
        device.check("rtcSetSceneFlags")?;
        if !triangles.is_empty() {
            attach_mesh(device, raw, vertices, triangles, scene.factor)?;
        }
        // SAFETY: `raw` is live and no other thread can see it yet, so the commit cannot race with queries.
        unsafe { sys::rtcCommitScene(raw) };
        device.check("rtcCommitScene")?;
        Ok(scene)
    }
}

/// Creates a triangle geometry from `vertices` and `triangles` (already validated), attaches it to `scene` and
/// releases our reference to it (the scene keeps its own).
fn attach_mesh(
    device: &DeviceInner,
    scene: sys::RTCScene,
    vertices: &[Vec3],
    triangles: &[[u32; 3]],
    factor: f32,
) -> Result<(), EmbreeError> {
    // SAFETY: `device.raw` is a live device.
    let geometry = unsafe { sys::rtcNewGeometry(device.raw, sys::RTCGeometryType::TRIANGLE) };
    device.check("rtcNewGeometry")?;
    let result = fill_and_attach(device, scene, geometry, vertices, triangles, factor);
    // SAFETY: `geometry` came from `rtcNewGeometry` and this is the only release of our reference; if it was
    // attached, the scene holds its own reference.
    unsafe { sys::rtcReleaseGeometry(geometry) };
    result
}

fn fill_and_attach(
    device: &DeviceInner,
    scene: sys::RTCScene,
    geometry: sys::RTCGeometry,
    vertices: &[Vec3],
    triangles: &[[u32; 3]],
    factor: f32,
) -> Result<(), EmbreeError> {
    fill_buffer(device, geometry, vertices.iter().map(|v| (*v * factor).to_array()))?;
    fill_buffer(device, geometry, triangles.iter().copied())?;
    // SAFETY: `geometry` is live with both buffers filled; `scene` is live and not yet committed or shared.
    unsafe {
        sys::rtcCommitGeometry(geometry);
        sys::rtcAttachGeometry(scene, geometry);
    }
    device.check("rtcAttachGeometry")
}

/// A 4-byte scalar of an Embree triangle-geometry buffer, with the buffer it fills: `f32` the vertex
/// coordinates, `u32` the vertex indices of the triangles.
trait BufferScalar: Copy {
    /// The buffer.
    const KIND: sys::RTCBufferType;
    /// Its item format (three scalars).
    const FORMAT: sys::RTCFormat;
    /// The call that creates it, as errors name it.
    const OPERATION: &'static str;
}

impl BufferScalar for f32 {
    const KIND: sys::RTCBufferType = sys::RTCBufferType::VERTEX;
    const FORMAT: sys::RTCFormat = sys::RTCFormat::FLOAT3;
    const OPERATION: &'static str = "rtcSetNewGeometryBuffer(VERTEX)";
}

impl BufferScalar for u32 {
    const KIND: sys::RTCBufferType = sys::RTCBufferType::INDEX;
    const FORMAT: sys::RTCFormat = sys::RTCFormat::UINT3;
    const OPERATION: &'static str = "rtcSetNewGeometryBuffer(INDEX)";
}

/// Asks Embree for `T`'s new buffer of `geometry` holding `items.len()` items, three `T` each with a tight
/// stride, and fills it with `items`.
fn fill_buffer<T: BufferScalar>(
    device: &DeviceInner,
    geometry: sys::RTCGeometry,
    items: impl ExactSizeIterator<Item = [T; 3]>,
) -> Result<(), EmbreeError> {
    let operation = T::OPERATION;
    let count = items.len();
    // SAFETY: `geometry` is a live triangle geometry. We ask Embree to allocate a buffer of `count` items with
    // a stride of three `T`; Embree pads such buffers so vector loads past the last item stay in bounds.
    let buffer =
        unsafe { sys::rtcSetNewGeometryBuffer(geometry, T::KIND, 0, T::FORMAT, 3 * size_of::<T>(), count) };
    device.check(operation)?;
    if buffer.is_null() {
        return Err(EmbreeError::Device {
            code: ErrorCode::Unknown,
            operation,
            message: "Embree returned no buffer".to_owned(),
        });
    }
    // SAFETY: Embree returned a non-null buffer of `count * 3` 4-byte scalars, aligned for them (Embree aligns
    // buffers to at least 16 bytes), exclusively ours until the commit; `T` is `f32` or `u32` (`BufferScalar`).
    let out = unsafe { std::slice::from_raw_parts_mut(buffer.cast::<T>(), count * 3) };
    for (o, item) in out.chunks_exact_mut(3).zip(items) {
        o.copy_from_slice(&item);
    }
    Ok(())
}

/// Options for building a scene.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SceneOptions {
    /// Sets Embree's `RTC_SCENE_FLAG_ROBUST`: a slower traversal that avoids optimizations which may miss hits
    /// on shared edges and vertices ("watertight" traversal). Use it when rays graze edges (contact edges).
    pub robust: bool,
}

/// The Embree form of `ray` in the scene scaled by `factor` (a negative `tnear` raised to 0, all mask bits set),
/// and the power of two `u` by which Embree's `t` is to be multiplied to give the ray's own `t`.
///
/// The origin is scaled by `factor`; the direction by `factor` and then by the [`unit_factor`] of its length, so
/// that Embree sees a direction of length in `[1, 2)` whatever length the caller chose: a unit direction in a
/// scene of size 2^60 would otherwise reach Embree with components below `1e-18`, where its traversal replaces
/// reciprocals by a constant (`rcp_safe`) and rays miss. `tnear` and `tfar` are divided by that second factor
/// (`u`), so the ray covers the same points. Every scaling is by a power of two, hence exact.
fn to_raw(ray: &Ray, factor: f32) -> (sys::RTCRay, f32) {
    // In f64: the squares of a large or tiny direction's components would overflow or underflow f32.
    let length = (ray.direction.as_dvec3() * f64::from(factor)).length() as f32;
    let u = unit_factor(length);
    // Embree's point `factor * origin + t' * factor * u * direction` is `factor` times the ray's point at
    // `t = t' * u`.
    let (origin, direction) = (ray.origin * factor, ray.direction * (factor * u));
    let raw = sys::RTCRay {
        org_x: origin.x,
        org_y: origin.y,
        org_z: origin.z,
        tnear: ray.tnear.max(0.0) / u,
        dir_x: direction.x,
        dir_y: direction.y,
        dir_z: direction.z,
        time: 0.0,
        tfar: ray.tfar / u,
        mask: u32::MAX,
        id: 0,
        flags: 0,
    };
    (raw, u)
}

/// A committed triangle scene, ready for queries from any number of threads.
pub struct TriangleScene {
    raw: sys::RTCScene,
    // Keeps the device, and the error sink its callback writes to, alive while the scene exists.
    _device: Arc<DeviceInner>,
    triangle_count: usize,
    scale: f32,
    /// [`unit_factor`] of `scale`: Embree holds the vertices times this, and every ray is scaled by it too.
    factor: f32,
}

// SAFETY: a committed scene is never modified through this type (no method takes `&mut self` or changes the scene),
// and Embree documents that `rtcIntersect*` / `rtcOccluded*` on a committed scene may be called from many threads at
// once ("The modification of a geometry, committing the scene, and tracing of rays must always happen sequentially",
// rtcCommitScene(3); queries themselves only read the built acceleration structure). The handle is reference-counted,
// so releasing it in `Drop` on another thread is fine; the `Arc<DeviceInner>` is `Send + Sync`.
unsafe impl Send for TriangleScene {}
// SAFETY: see `Send`: shared references only run read-only queries on the committed scene.
unsafe impl Sync for TriangleScene {}

impl fmt::Debug for TriangleScene {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("TriangleScene")
            .field("triangle_count", &self.triangle_count)
            .field("scale", &self.scale)
            .field("factor", &self.factor)
            .finish_non_exhaustive()
    }
}

impl Drop for TriangleScene {
    fn drop(&mut self) {
        // SAFETY: `self.raw` came from `rtcNewScene` and this is our only release; `&mut self` means no query is
        // running on it.
        unsafe { sys::rtcReleaseScene(self.raw) };
    }
}

/// Arguments for `rtcOccluded*` as `rtcInitOccludedArguments` (an inline C function the bindings lack) sets them.
fn occluded_args() -> sys::RTCOccludedArguments {
    sys::RTCOccludedArguments {
        flags: sys::RTCRayQueryFlags::INCOHERENT,
        feature_mask: sys::RTCFeatureFlags::RTC_FEATURE_FLAG_ALL,
        context: std::ptr::null_mut(),
        filter: None,
        occluded: None,
    }
}

/// A 16-lane valid mask: `-1` for active lanes, `0` for inactive. Embree requires 64-byte alignment for it.
#[repr(C, align(64))]
struct ValidMask16([i32; 16]);

impl TriangleScene {
    /// Number of triangles in the scene.
    #[must_use]
    pub fn triangle_count(&self) -> usize {
        self.triangle_count
    }

    /// The absolute offset (scene units) to cut from both ends of a segment between two surface points:
    /// [`crate::raycast::offset_for`] of the scene's vertices. See [`Ray::segment`].
    #[must_use]
    pub fn offset(&self) -> f32 {
        self.scale * RELATIVE_OFFSET
    }

    /// Whether anything in the scene lies on `ray` (any hit with `tnear < t <= tfar`).
    #[must_use]
    pub fn occluded(&self, ray: &Ray) -> bool {
        if ray.is_empty() {
            return false;
        }
        let (mut raw, _) = to_raw(ray, self.factor);
        let mut args = occluded_args();
        // SAFETY: `self.raw` is a committed scene (see the `Sync` impl); `raw` and `args` are valid, properly
        // aligned (`RTCRay` is `repr(align(16))`) locals that outlive the call.
        unsafe { sys::rtcOccluded1(self.raw, &mut raw, &mut args) };
        raw.tfar == f32::NEG_INFINITY
    }

    /// Tests up to 16 rays in one packet (`rtcOccluded16` with a valid mask); bit `k` of the result is set if
    /// `rays[k]` is occluded.
    ///
    /// # Panics
    /// If `rays.len() > 16`.
    #[must_use]
    pub fn occluded16(&self, rays: &[Ray]) -> u16 {
        assert!(rays.len() <= 16, "occluded16 takes at most 16 rays, got {}", rays.len());
        let mut packet = sys::RTCRay16 {
            org_x: [0.0; 16],
            org_y: [0.0; 16],
            org_z: [0.0; 16],
            tnear: [0.0; 16],
            dir_x: [0.0; 16],
            dir_y: [0.0; 16],
            dir_z: [1.0; 16],
            time: [0.0; 16],
            tfar: [0.0; 16],
            mask: [u32::MAX; 16],
            id: [0; 16],
            flags: [0; 16],
        };
        let mut valid = ValidMask16([0; 16]);
        for (k, ray) in rays.iter().enumerate() {
            if ray.is_empty() {
                continue;
            }
            let (r, _) = to_raw(ray, self.factor);
            packet.org_x[k] = r.org_x;
            packet.org_y[k] = r.org_y;
            packet.org_z[k] = r.org_z;
            packet.tnear[k] = r.tnear;
            packet.dir_x[k] = r.dir_x;
            packet.dir_y[k] = r.dir_y;
            packet.dir_z[k] = r.dir_z;
            packet.tfar[k] = r.tfar;
            packet.id[k] = k as u32;
            valid.0[k] = -1;
        }
        if valid.0.iter().all(|&v| v == 0) {
            return 0;
        }
        let mut args = occluded_args();
        // SAFETY: `self.raw` is a committed scene; `packet` is `RTCRay16` (`repr(align(64))`) and `valid` is a
        // 64-byte aligned array of 16 ints, as `rtcOccluded16` requires; inactive lanes are ignored by Embree; all
        // three locals outlive the call.
        unsafe { sys::rtcOccluded16(valid.0.as_ptr(), self.raw, &mut packet, &mut args) };
        let mut bits = 0u16;
        for k in 0..rays.len() {
            if valid.0[k] != 0 && packet.tfar[k] == f32::NEG_INFINITY {
                bits |= 1 << k;
            }
        }
        bits
    }

    /// Tests any number of rays in packets of 16; `occluded[k]` is set for `rays[k]`.
    ///
    /// # Panics
    /// If `occluded.len() != rays.len()`.
    pub fn occluded_many(&self, rays: &[Ray], occluded: &mut [bool]) {
        assert_eq!(rays.len(), occluded.len(), "one output per ray");
        for (chunk, out) in rays.chunks(16).zip(occluded.chunks_mut(16)) {
            let bits = self.occluded16(chunk);
            for (k, o) in out.iter_mut().enumerate() {
                *o = bits & (1 << k) != 0;
            }
        }
    }

    /// The closest hit on `ray` within `(tnear, tfar]`, if any.
    #[must_use]
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        if ray.is_empty() {
            return None;
        }
        let (raw, u) = to_raw(ray, self.factor);
        let mut rayhit = sys::RTCRayHit {
            ray: raw,
            hit: sys::RTCHit {
                Ng_x: 0.0,
                Ng_y: 0.0,
                Ng_z: 0.0,
                u: 0.0,
                v: 0.0,
                primID: sys::RTC_INVALID_GEOMETRY_ID,
                geomID: sys::RTC_INVALID_GEOMETRY_ID,
                instID: [sys::RTC_INVALID_GEOMETRY_ID],
            },
        };
        let mut args = sys::RTCIntersectArguments {
            flags: sys::RTCRayQueryFlags::INCOHERENT,
            feature_mask: sys::RTCFeatureFlags::RTC_FEATURE_FLAG_ALL,
            context: std::ptr::null_mut(),
            filter: None,
            intersect: None,
        };
        // SAFETY: `self.raw` is a committed scene; `rayhit` (`repr(align(16))`) and `args` are initialized locals
        // that outlive the call; `geomID` starts as RTC_INVALID_GEOMETRY_ID as Embree requires.
        unsafe { sys::rtcIntersect1(self.raw, &mut rayhit, &mut args) };
        let hit = rayhit.hit;
        if hit.geomID == sys::RTC_INVALID_GEOMETRY_ID {
            return None;
        }
        // Embree's unnormalized triangle Ng is parallel to (p1 - p0) x (p2 - p0) (the orientation documented on
        // `Hit::normal`); a test checks it.
        let normal = Vec3::new(hit.Ng_x, hit.Ng_y, hit.Ng_z).normalize_or_zero();
        Some(Hit {
            // Back to the ray's own parameter (exact: `u` is a power of two).
            t: rayhit.ray.tfar * u,
            primitive: hit.primID,
            geometry: hit.geomID,
            barycentric: [hit.u, hit.v],
            normal,
        })
    }
}

impl RayCaster for TriangleScene {
    fn offset(&self) -> f32 {
        TriangleScene::offset(self)
    }

    fn occluded(&self, ray: &Ray) -> bool {
        TriangleScene::occluded(self, ray)
    }

    fn occluded_many(&self, rays: &[Ray], occluded: &mut [bool]) {
        TriangleScene::occluded_many(self, rays, occluded);
    }

    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        TriangleScene::intersect(self, ray)
    }
}
