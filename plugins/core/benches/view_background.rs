//! The view-following background (`avatarm_core::dr::view_background`) on one thread against
//! all of the machine's, measured in the same run: re-projecting the robot's region of a
//! 640x480 head camera from 8 views, and a new view's rectangle map.
//! `cargo bench -p avatarm_core --bench view_background`.

mod common;

use std::hint::black_box;
use std::time::Instant;

use avatarm_core::dr::RgbaView;
use avatarm_core::dr::view_background::{BackgroundViews, GeometricProxy, default_threads};
use avatarm_core::prelude::{Intrinsics, PinholeCamera};
use common::median;
use criterion::{BenchmarkId, Criterion};
use nalgebra::Isometry3;

const W: u32 = 640;
const H: u32 = 480;

/// A head at the side of the desk, 1.2 m from the arm, turned `yaw_deg` about the vertical.
fn head(yaw_deg: f64) -> PinholeCamera {
    let yaw = yaw_deg.to_radians();
    let eye = [1.2, -0.4, 1.35];
    let target = [eye[0] - 1.2 * yaw.cos(), eye[1] + 1.2 * yaw.sin(), 0.85];
    PinholeCamera::looking_at(
        Intrinsics::from_fov_y(55f64.to_radians(), W, H),
        eye,
        target,
    )
    .expect("pose")
}

/// The room: a wall, a floor and a desk.
fn room() -> GeometricProxy {
    GeometricProxy::from_boxes(&[
        (Isometry3::translation(-0.6, 0.0, 1.5), [0.02, 4.0, 3.0]),
        (Isometry3::translation(0.5, 0.0, -0.01), [4.0, 4.0, 0.02]),
        (Isometry3::translation(0.0, 0.0, 0.37), [0.8, 1.4, 0.74]),
    ])
}

/// A textured frame (what a camera would show; the colours do not change the cost).
fn frame(seed: u32) -> Vec<u8> {
    (0..W * H)
        .flat_map(|i| {
            let (x, y) = (i % W, i / W);
            let v = (x * 7 + y * 13 + seed * 31) as u8;
            [v, v.wrapping_mul(3), 255 - v, 255]
        })
        .collect()
}

/// 8 views from -15° to 15°, the robot's region (an ellipse over a fifth of the frame) to
/// render, and the camera to render it from.
fn inputs() -> (BackgroundViews, Vec<u8>, PinholeCamera) {
    let mut views = BackgroundViews::new(W, H, room(), 8, 0.0).expect("views");
    let covered: Vec<u8> = (0..W * H)
        .map(|i| {
            let (x, y) = (
                f64::from(i % W) / f64::from(W),
                f64::from(i / W) / f64::from(H),
            );
            u8::from((x - 0.5).powi(2) / 0.09 + (y - 0.5).powi(2) / 0.16 < 0.5)
        })
        .collect();
    for k in 0..8u32 {
        let data = frame(k);
        let view = RgbaView::new("view", W, H, &data).expect("size");
        let yaw = -15.0 + 30.0 * f64::from(k) / 7.0;
        views
            .offer(&head(yaw), &view, &covered, f64::from(k))
            .expect("offer");
    }
    assert_eq!(views.len(), 8);
    (views, covered, head(3.0))
}

fn benches(c: &mut Criterion) {
    let (mut views, region, target) = inputs();
    let proxy = room();
    let mut group = c.benchmark_group("view_background");
    group.sample_size(20);
    let all = default_threads();
    // One pass on one core (criterion refuses a benchmark id twice in a group).
    for threads in if all > 1 { vec![1, all] } else { vec![1] } {
        views.threads = threads;
        group.bench_function(BenchmarkId::new("render_region", threads), |b| {
            b.iter(|| views.render(black_box(&target), None, Some(&region)));
        });
        group.bench_function(BenchmarkId::new("rect_map", threads), |b| {
            b.iter(|| proxy.rect_map(black_box(&target), threads));
        });
    }
    group.finish();
}

/// One thread against all, from timings interleaved in one loop (so both see the same machine
/// state); criterion's own report above has the statistics of each.
fn ratios() {
    let (mut views, region, target) = inputs();
    let proxy = room();
    let all = default_threads();
    let (mut one, mut many, mut map_one, mut map_many) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for _ in 0..15 {
        views.threads = 1;
        let t = Instant::now();
        black_box(views.render(&target, None, Some(&region)).expect("render"));
        one.push(t.elapsed());
        views.threads = all;
        let t = Instant::now();
        black_box(views.render(&target, None, Some(&region)).expect("render"));
        many.push(t.elapsed());
        let t = Instant::now();
        black_box(proxy.rect_map(&target, 1));
        map_one.push(t.elapsed());
        let t = Instant::now();
        black_box(proxy.rect_map(&target, all));
        map_many.push(t.elapsed());
    }
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    println!("\n{W}x{H}, 8 views, medians of 15 interleaved runs, 1 thread against {all}:");
    for (what, one, many) in [
        ("render of the robot's region", median(one), median(many)),
        (
            "a new view's rectangle map",
            median(map_one),
            median(map_many),
        ),
    ] {
        println!(
            "  {what}: {:.2} ms against {:.2} ms, {:.2}x faster",
            ms(one),
            ms(many),
            one.as_secs_f64() / many.as_secs_f64().max(1e-12)
        );
    }
}

fn main() {
    let mut c = Criterion::default().configure_from_args();
    benches(&mut c);
    c.final_summary();
    ratios();
}
