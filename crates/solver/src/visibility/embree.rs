//! Intel Embree 3 (the C library of Debian's `libembree-dev`) as the occluders' index, behind
//! the `embree` feature: the same faces in the same f32 frame, queried with `rtcOccluded1` and
//! `rtcIntersect1`. Only the few calls used are declared here, after
//! `/usr/include/embree3/rtcore_*.h` (3.13); faces a query must ignore (the segment's own) are
//! dropped by an intersection-context filter.

use glam::Vec3A;
use std::ffi::c_void;

type Device = *mut c_void;
type RawScene = *mut c_void;
type Geometry = *mut c_void;

const GEOMETRY_TYPE_QUAD: u32 = 1;
const BUFFER_TYPE_INDEX: u32 = 0;
const BUFFER_TYPE_VERTEX: u32 = 1;
const FORMAT_UINT4: u32 = 0x5004;
const FORMAT_FLOAT3: u32 = 0x9003;
const SCENE_FLAG_ROBUST: u32 = 1 << 2;
const SCENE_FLAG_CONTEXT_FILTER_FUNCTION: u32 = 1 << 3;
const BUILD_QUALITY_HIGH: u32 = 2;
const INVALID_ID: u32 = u32::MAX;

/// `RTCFilterFunctionNArguments`.
#[repr(C)]
struct FilterArguments {
    valid: *mut i32,
    geometry_user: *mut c_void,
    context: *const Context,
    ray: *mut c_void,
    hit: *const c_void,
    n: u32,
}

/// `RTCIntersectContext` (with `RTC_MAX_INSTANCE_LEVEL_COUNT` 1 and no minimum width).
#[repr(C)]
struct Context {
    flags: u32,
    filter: Option<unsafe extern "C" fn(*const FilterArguments)>,
    instance_ids: [u32; 1],
}

/// A query's context and the two faces it ignores: the filter finds them behind the context
/// pointer Embree hands it.
#[repr(C)]
struct Query {
    context: Context,
    ignore: [u32; 2],
}

/// `RTCRay`.
#[repr(C, align(16))]
#[derive(Clone, Copy)]
struct Ray {
    origin: [f32; 3],
    tnear: f32,
    direction: [f32; 3],
    time: f32,
    tfar: f32,
    mask: u32,
    id: u32,
    flags: u32,
}

/// `RTCHit`.
#[repr(C, align(16))]
#[derive(Clone, Copy)]
struct Hit {
    normal: [f32; 3],
    u: f32,
    v: f32,
    primitive: u32,
    geometry: u32,
    instance_ids: [u32; 1],
}

/// `RTCRayHit`.
#[repr(C)]
struct RayHit {
    ray: Ray,
    hit: Hit,
}

#[link(name = "embree3")]
unsafe extern "C" {
    fn rtcNewDevice(config: *const std::ffi::c_char) -> Device;
    fn rtcReleaseDevice(device: Device);
    fn rtcNewScene(device: Device) -> RawScene;
    fn rtcReleaseScene(scene: RawScene);
    fn rtcSetSceneFlags(scene: RawScene, flags: u32);
    fn rtcSetSceneBuildQuality(scene: RawScene, quality: u32);
    fn rtcNewGeometry(device: Device, kind: u32) -> Geometry;
    fn rtcSetNewGeometryBuffer(
        geometry: Geometry,
        kind: u32,
        slot: u32,
        format: u32,
        stride: usize,
        count: usize,
    ) -> *mut c_void;
    fn rtcCommitGeometry(geometry: Geometry);
    fn rtcAttachGeometry(scene: RawScene, geometry: Geometry) -> u32;
    fn rtcReleaseGeometry(geometry: Geometry);
    fn rtcCommitScene(scene: RawScene);
    fn rtcOccluded1(scene: RawScene, context: *mut Context, ray: *mut Ray);
    fn rtcIntersect1(scene: RawScene, context: *mut Context, ray_hit: *mut RayHit);
}

/// Drops hits on the query's ignored faces. For one ray (N = 1) the hit is laid out as
/// `RTCHit`, whose primitive id is the face's place among the indexed ones.
unsafe extern "C" fn ignore_own_faces(arguments: *const FilterArguments) {
    // SAFETY: Embree passes valid arguments for the one ray of an `rtcOccluded1` or
    // `rtcIntersect1` call, whose context is the `Query` built by `Scene::query`.
    unsafe {
        let arguments = &*arguments;
        let query = &*(arguments.context as *const Query);
        let hit = &*(arguments.hit as *const Hit);
        if query.ignore.contains(&hit.primitive) {
            *arguments.valid = 0;
        }
    }
}

/// An Embree device and a committed scene of the indexed faces, as quads (a triangle repeats
/// its last corner, as Embree's quad meshes allow).
pub struct Scene {
    device: Device,
    scene: RawScene,
}

// SAFETY: a committed Embree scene is immutable, and Embree documents its ray queries as safe to
// call from any number of threads at once.
unsafe impl Send for Scene {}
unsafe impl Sync for Scene {}

impl Drop for Scene {
    fn drop(&mut self) {
        // SAFETY: both were made by `Scene::new` and are released once.
        unsafe {
            rtcReleaseScene(self.scene);
            rtcReleaseDevice(self.device);
        }
    }
}

impl Scene {
    /// The scene of `faces` (corners and corner count each, in the occluders' frame); `None`
    /// when Embree cannot start (no supported CPU).
    pub fn new(faces: &[([Vec3A; 4], usize)]) -> Option<Scene> {
        // SAFETY: every pointer passed is one Embree returned, checked for null, and the
        // buffers are written within the item counts they were made with.
        unsafe {
            let device = rtcNewDevice(std::ptr::null());
            if device.is_null() {
                return None;
            }
            let scene = rtcNewScene(device);
            rtcSetSceneFlags(
                scene,
                SCENE_FLAG_ROBUST | SCENE_FLAG_CONTEXT_FILTER_FUNCTION,
            );
            rtcSetSceneBuildQuality(scene, BUILD_QUALITY_HIGH);
            let geometry = rtcNewGeometry(device, GEOMETRY_TYPE_QUAD);
            let vertices = rtcSetNewGeometryBuffer(
                geometry,
                BUFFER_TYPE_VERTEX,
                0,
                FORMAT_FLOAT3,
                12,
                faces.len() * 4,
            ) as *mut [f32; 3];
            let indices = rtcSetNewGeometryBuffer(
                geometry,
                BUFFER_TYPE_INDEX,
                0,
                FORMAT_UINT4,
                16,
                faces.len(),
            ) as *mut [u32; 4];
            for (f, (corners, arity)) in faces.iter().enumerate() {
                let base = 4 * f as u32;
                for k in 0..4 {
                    let corner = corners[k.min(arity - 1)];
                    *vertices.add(4 * f + k) = corner.to_array();
                }
                *indices.add(f) = [base, base + 1, base + 2, base + 3];
            }
            rtcCommitGeometry(geometry);
            rtcAttachGeometry(scene, geometry);
            rtcReleaseGeometry(geometry);
            rtcCommitScene(scene);
            Some(Scene { device, scene })
        }
    }

    fn query(ignore: [u32; 2]) -> Query {
        Query {
            context: Context {
                flags: 0,
                filter: Some(ignore_own_faces),
                instance_ids: [INVALID_ID],
            },
            ignore,
        }
    }

    fn ray(origin: Vec3A, direction: Vec3A, tnear: f32, tfar: f32) -> Ray {
        Ray {
            origin: origin.to_array(),
            tnear,
            direction: direction.to_array(),
            time: 0.0,
            tfar,
            mask: u32::MAX,
            id: 0,
            flags: 0,
        }
    }

    /// Whether no face but those of `ignore` (places among the indexed faces) meets the ray
    /// between `tnear` and `tfar`.
    pub fn is_clear(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        (tnear, tfar): (f32, f32),
        ignore: [u32; 2],
    ) -> bool {
        let mut query = Self::query(ignore);
        let mut ray = Self::ray(origin, direction, tnear, tfar);
        // SAFETY: the scene is committed; the context is the first field of `query`, as the
        // filter expects.
        unsafe { rtcOccluded1(self.scene, &mut query.context, &mut ray) };
        // Embree marks an occluded ray by setting its tfar to minus infinity.
        ray.tfar != f32::NEG_INFINITY
    }

    /// The first face (place among the indexed faces) the ray meets past `tnear` but `ignore`,
    /// and its parameter.
    pub fn first_hit(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        tnear: f32,
        ignore: u32,
    ) -> Option<(u32, f32)> {
        let mut query = Self::query([ignore, INVALID_ID]);
        let mut ray_hit = RayHit {
            ray: Self::ray(origin, direction, tnear, f32::INFINITY),
            hit: Hit {
                normal: [0.0; 3],
                u: 0.0,
                v: 0.0,
                primitive: INVALID_ID,
                geometry: INVALID_ID,
                instance_ids: [INVALID_ID],
            },
        };
        // SAFETY: as in `is_clear`.
        unsafe { rtcIntersect1(self.scene, &mut query.context, &mut ray_hit) };
        (ray_hit.hit.geometry != INVALID_ID).then_some((ray_hit.hit.primitive, ray_hit.ray.tfar))
    }
}
