use parry3d::math::Vector as PVec;
use parry3d::query::{Ray, RayCast};
use parry3d::shape::Cuboid;

use super::Slab;
use crate::rng::Pcg32;

/// What the renderer did before the slab loop: one parry call per pixel.
fn parry_depth(slab: &Slab, ray: [f32; 2], depth: f32) -> f32 {
    let [rx, ry] = ray;
    let rb = slab.rb;
    let dir = PVec::new(
        rb[0][0] * rx + rb[0][1] * ry + rb[0][2],
        rb[1][0] * rx + rb[1][1] * ry + rb[1][2],
        rb[2][0] * rx + rb[2][1] * ry + rb[2][2],
    );
    let origin = PVec::new(slab.origin[0], slab.origin[1], slab.origin[2]);
    let cuboid = Cuboid::new(PVec::new(slab.half[0], slab.half[1], slab.half[2]));
    match cuboid.cast_local_ray(&Ray::new(origin, dir), depth.min(slab.far), true) {
        Some(t) => depth.min(t),
        None => depth,
    }
}

#[test]
fn the_slab_loop_gives_parrys_depths_bit_for_bit() {
    let mut rng = Pcg32::new(7);
    let mut u = |lo: f32, hi: f32| lo + (hi - lo) * rng.uniform() as f32;
    let (mut hits, mut inside) = (0, 0);
    for _ in 0..200 {
        let angle = u(-3.2, 3.2);
        let (s, c) = angle.sin_cos();
        let tilt = u(-0.5, 0.5);
        let slab = Slab {
            half: [u(0.05, 3.0), u(0.05, 3.0), u(0.05, 2.0)],
            origin: [u(-6.0, 6.0), u(-6.0, 6.0), u(-3.0, 4.0)],
            rb: [[c, -s, tilt], [s, c, 0.0], [0.0, tilt, 1.0]],
            far: 15.0,
        };
        // Rays across a 90 deg view, an exact zero direction component among them.
        let rays: Vec<[f32; 2]> = (0..64)
            .map(|k| {
                if k == 0 {
                    [0.0, 0.0]
                } else {
                    [u(-1.0, 1.0), u(-1.0, 1.0)]
                }
            })
            .collect();
        let before: Vec<f32> = rays.iter().map(|_| u(0.1, 20.0)).collect();
        let mut depth = before.clone();
        slab.cast_row(&rays, &mut depth);
        for ((ray, &d0), &d) in rays.iter().zip(&before).zip(&depth) {
            let want = parry_depth(&slab, *ray, d0);
            assert_eq!(
                d.to_bits(),
                want.to_bits(),
                "ray {ray:?} from {:?}",
                slab.origin
            );
            hits += usize::from(d < d0);
            inside += usize::from(d == 0.0);
        }
    }
    // The rays hit boxes, and some start inside one: both branches were compared.
    assert!(hits > 500, "{hits} hits");
    assert!(inside > 50, "{inside} rays from inside");
}
