//! CPU twin of `differential.wgsl`: what one receiver's sums are, with the same shadow rays
//! (`twin::bvh::Bvh::occluded`, the GPU traversal's twin, from `p + n RAY_OFFSET` to
//! `l + n_l RAY_OFFSET`).

use crate::twin::bvh::Bvh;
use crate::twin::exact_cpu::RAY_OFFSET;
use crate::twin::{Val, val_geometry};
use glam::Vec3;

/// A real surface point that receives light: world position (m) and unit normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Receiver {
    pub position: Vec3,
    pub normal: Vec3,
}

/// What the virtual content does to one receiver's irradiance (W/m², RGB).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ReceiverLight {
    /// Irradiance of every real VAL, no visibility: what the receiver gets without the virtual
    /// content (the real room's own occlusion is already in the camera image).
    pub unoccluded: Vec3,
    /// The part of `unoccluded` whose shadow ray a virtual triangle blocks.
    pub blocked: Vec3,
    /// Irradiance of the virtual re-emitters whose shadow ray is free.
    pub added: Vec3,
}

impl ReceiverLight {
    /// The change the virtual content makes: `added - blocked` (W/m²).
    pub fn change(&self) -> Vec3 {
        self.added - self.blocked
    }
}

/// The sums of `differential.wgsl` at `receiver`: `vals[.. real_count]` are real VALs, the
/// rest the virtual content's re-emitters; `bvh` is over the virtual triangles
/// (`positions`, `triangles`).
pub fn receiver_light(
    receiver: &Receiver,
    vals: &[Val],
    real_count: usize,
    bvh: &Bvh,
    positions: &[Vec3],
    triangles: &[[u32; 3]],
) -> ReceiverLight {
    receiver_light_with(receiver, vals, real_count, |origin, target| bvh.occluded(positions, triangles, origin, target))
}

/// The sums at `receiver`, with `blocked(from, to)` deciding each shadow ray.
fn receiver_light_with(
    receiver: &Receiver,
    vals: &[Val],
    real_count: usize,
    blocked: impl Fn(Vec3, Vec3) -> bool,
) -> ReceiverLight {
    let origin = receiver.position + receiver.normal * RAY_OFFSET;
    let mut sums = ReceiverLight::default();
    for (j, val) in vals.iter().enumerate() {
        let g = val_geometry(receiver.position, receiver.normal, val.position, val.normal, val.area);
        let f = g.weight * g.cos_receiver;
        if f <= 0.0 {
            continue;
        }
        let e = val.flux * f;
        let blocked = blocked(origin, val.position + val.normal * RAY_OFFSET);
        if j < real_count {
            sums.unoccluded += e;
            if blocked {
                sums.blocked += e;
            }
        } else if !blocked {
            sums.added += e;
        }
    }
    sums
}
