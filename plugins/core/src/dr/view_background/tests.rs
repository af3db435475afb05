//! Tests of [`super`] (view_background).

use super::*;
use crate::vision::camera::Intrinsics;

fn camera(eye: [f64; 3], target: [f64; 3]) -> PinholeCamera {
    PinholeCamera::looking_at(
        Intrinsics::from_fov_y(50f64.to_radians(), 64, 48),
        eye,
        target,
    )
    .expect("pose")
}

/// A desk (a box) before a wall, and two cameras 2.2° apart that see the desk's top and front
/// and the wall behind: edges where rectangles meet, in both views.
fn desk_before_wall() -> (GeometricProxy, PinholeCamera, PinholeCamera) {
    let proxy = GeometricProxy::from_boxes(&[
        (Isometry3::translation(-0.01, 0.0, 0.0), [0.02, 4.0, 3.0]),
        (Isometry3::translation(0.5, 0.0, 0.35), [0.6, 1.6, 0.7]),
    ]);
    let a = camera([1.8, -0.3, 1.2], [0.3, 0.0, 0.6]);
    let b = camera([1.75, -0.22, 1.24], [0.3, 0.05, 0.6]);
    (proxy, a, b)
}

/// A wall at x = 0 (a thin box) whose colour is a function of the point: what a view sees
/// at each pixel, computed exactly.
fn wall() -> GeometricProxy {
    GeometricProxy::from_boxes(&[(Isometry3::translation(-0.01, 0.0, 0.0), [0.02, 4.0, 3.0])])
}

fn paint(p: &Point3<f64>) -> [u8; 3] {
    [
        (128.0 + 100.0 * (p.y * 2.0).sin()) as u8,
        (128.0 + 100.0 * (p.z * 3.0).cos()) as u8,
        90,
    ]
}

fn photograph(proxy: &GeometricProxy, cam: &PinholeCamera) -> Vec<u8> {
    let k = &cam.intrinsics;
    let origin = Point3::from(cam.world_from_camera.translation.vector);
    let mut out = Vec::new();
    for y in 0..k.height {
        for x in 0..k.width {
            let dir = cam.ray(f64::from(x), f64::from(y));
            let c = match proxy.hit(&origin, &dir) {
                Some((_, t)) => paint(&(origin + dir * t)),
                None => [0, 0, 0],
            };
            out.extend_from_slice(&[c[0], c[1], c[2], 255]);
        }
    }
    out
}

/// The room photographed from `a`, kept as the only view, and rendered from `b`: the
/// views, the rendering and `b`'s own photograph (the truth).
fn one_view_seen_from(
    proxy: &GeometricProxy,
    a: &PinholeCamera,
    b: &PinholeCamera,
) -> (BackgroundViews, RenderedBackground, Vec<u8>) {
    let mut views = BackgroundViews::new(64, 48, proxy.clone(), 4, 0.0).expect("views");
    let photo = photograph(proxy, a);
    let frame = RgbaView::new("a", 64, 48, &photo).expect("view");
    assert!(
        views
            .offer(a, &frame, &vec![0; 64 * 48], 0.0)
            .expect("offer")
    );
    let out = views.render(b, None, None).expect("render");
    (views, out, photograph(proxy, b))
}

#[test]
fn a_box_has_six_faces_and_the_nearest_is_hit() {
    let proxy = GeometricProxy::from_boxes(&[(Isometry3::identity(), [1.0, 2.0, 0.5])]);
    assert_eq!(proxy.rects.len(), 6);
    // From above, straight down: the top face at z = 0.5.
    let (i, t) = proxy
        .hit(&Point3::new(0.1, 0.2, 2.0), &-Vector3::z())
        .expect("hit");
    assert!((t - 1.5).abs() < 1e-12);
    assert!((proxy.rects[i].centre.z - 0.5).abs() < 1e-12);
    assert!(
        proxy
            .hit(&Point3::new(3.0, 0.0, 2.0), &-Vector3::z())
            .is_none()
    );
}

#[test]
fn a_view_reprojects_exactly_through_a_plane_and_misses_stay_unseen() {
    let proxy = wall();
    let a = camera([1.5, -0.3, 1.0], [0.0, 0.0, 1.0]);
    let b = camera([1.4, 0.25, 1.05], [0.0, 0.1, 1.0]);
    let (views, out, truth) = one_view_seen_from(&proxy, &a, &b);
    let mut diffs = Vec::new();
    for i in 0..64 * 48 {
        if out.seen[i] > 0 {
            for c in 0..3 {
                diffs.push((i32::from(out.rgba[i * 4 + c]) - i32::from(truth[i * 4 + c])).abs());
            }
        }
    }
    let seen = out.seen.iter().filter(|&&s| s > 0).count();
    assert!(seen > 64 * 48 / 2, "most of b's view is in a's: {seen}");
    let mean = diffs.iter().sum::<i32>() as f64 / diffs.len() as f64;
    assert!(mean < 3.0, "bilinear resampling of a smooth wall: {mean}");
    // What a never saw stays unseen and keeps the fallback.
    let fallback = vec![7u8; 64 * 48 * 4];
    let out2 = views
        .render(&b, Some(fallback.clone()), None)
        .expect("render");
    for i in 0..64 * 48 {
        if out2.seen[i] == 0 {
            assert_eq!(out2.rgba[i * 4], 7);
        }
    }
    assert!(out2.seen.contains(&0), "b sees past a's edge");
    // Only where asked.
    let mut only = vec![0u8; 64 * 48];
    only[24 * 64 + 32] = 1;
    let out3 = views
        .render(&b, Some(fallback.clone()), Some(&only))
        .expect("render");
    assert_eq!(out3.seen.iter().filter(|&&s| s > 0).count(), 1);
    assert_eq!(out3.rgba[(24 * 64 + 32) * 4], out.rgba[(24 * 64 + 32) * 4]);
}

#[test]
fn where_two_rectangles_meet_the_seam_is_filled_from_the_texels_that_show_it() {
    // A desk (a box) before the wall: its top and front faces meet at an edge that both
    // cameras see, and the wall meets the desk's top behind it.
    let (proxy, a, b) = desk_before_wall();
    let (_, out, truth) = one_view_seen_from(&proxy, &a, &b);
    // Every pixel of b whose point a sees, a texel from its own rim, on the same rectangle,
    // is seen: none left along the edges where rectangles meet.
    let rects_a = proxy.rect_map(&a, 1);
    let origin = Point3::from(b.world_from_camera.translation.vector);
    let (mut checked, mut holes, mut seam) = (0, Vec::new(), 0);
    for y in 0..48u32 {
        for x in 0..64u32 {
            let Some((r, t)) = proxy.hit(&origin, &b.ray(f64::from(x), f64::from(y))) else {
                continue;
            };
            let p = origin + b.ray(f64::from(x), f64::from(y)) * t;
            let Some((u, v, _)) = a.project(&p) else {
                continue;
            };
            if !(1.0..62.0).contains(&u) || !(1.0..46.0).contains(&v) {
                continue;
            }
            let near = (v.round() as usize) * 64 + u.round() as usize;
            if rects_a[near] != r as u16 {
                continue;
            }
            checked += 1;
            let (x0, y0) = (u.floor() as usize, v.floor() as usize);
            let footprint =
                [(0, 0), (1, 0), (0, 1), (1, 1)].map(|(dx, dy)| rects_a[(y0 + dy) * 64 + x0 + dx]);
            if footprint.iter().any(|&q| q != r as u16) {
                seam += 1;
            }
            let i = (y * 64 + x) as usize;
            if out.seen[i] == 0 {
                holes.push((x, y));
            }
        }
    }
    assert!(checked > 64 * 48 / 2, "{checked}");
    assert!(seam > 20, "the views straddle edges: {seam} pixels");
    assert!(holes.is_empty(), "unseen on a seam: {holes:?}");
    // And what fills the seam is the room's colour there, as elsewhere.
    let mut diffs = Vec::new();
    for i in 0..64 * 48 {
        if out.seen[i] > 0 && truth[i * 4..i * 4 + 3] != [0, 0, 0] {
            for c in 0..3 {
                diffs.push((i32::from(out.rgba[i * 4 + c]) - i32::from(truth[i * 4 + c])).abs());
            }
        }
    }
    let mean = diffs.iter().sum::<i32>() as f64 / diffs.len() as f64;
    assert!(mean < 4.0, "{mean}");
}

#[test]
fn a_view_that_sees_a_point_through_few_texels_counts_for_less_in_the_blend() {
    let proxy = wall();
    // a is 1.9 deg from the target, b 3.8 deg: a outweighs b where it sees fully.
    let target = camera([1.5, 0.0, 1.0], [0.0, 0.0, 1.0]);
    let a = camera([1.5, 0.05, 1.0], [0.0, 0.0, 1.0]);
    let b = camera([1.5, -0.1, 1.0], [0.0, 0.0, 1.0]);
    // a's picture is wrong in blue (45 where the room is 90), and only every other texel
    // of every other row is usable, so its support runs from 0 to 1 across the wall.
    let wrong: Vec<u8> = photograph(&proxy, &a)
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2] / 2, 255])
        .collect();
    let lattice: Vec<u8> = (0..64 * 48)
        .map(|i| u8::from(!(i % 64 % 2 == 0 && i / 64 % 2 == 0)))
        .collect();
    let right = photograph(&proxy, &b);
    let mut views = BackgroundViews::new(64, 48, proxy.clone(), 4, 0.0).expect("views");
    let fa = RgbaView::new("a", 64, 48, &wrong).expect("a");
    let fb = RgbaView::new("b", 64, 48, &right).expect("b");
    assert!(views.offer(&a, &fa, &lattice, 0.0).expect("a"));
    assert!(views.offer(&b, &fb, &vec![0; 64 * 48], 1.0).expect("b"));
    let out = views.render(&target, None, None).expect("render");
    // a's share of each pixel's colour, read from blue: 90 is b's alone, 45 a's alone.
    let origin = Point3::from(target.world_from_camera.translation.vector);
    let (mut thin, mut full) = (Vec::new(), Vec::new());
    for y in 2..46u32 {
        for x in 2..62u32 {
            let dir = target.ray(f64::from(x), f64::from(y));
            let Some((r, t)) = proxy.hit(&origin, &dir) else {
                continue;
            };
            let Some((u, v, _)) = a.project(&(origin + dir * t)) else {
                continue;
            };
            let Some((_, support)) = views.views[0].sample(u, v, r as u16) else {
                continue;
            };
            let i = (y * 64 + x) as usize;
            let share = (90.0 - f64::from(out.rgba[i * 4 + 2])) / 45.0;
            if support < 0.1 {
                thin.push(share);
            } else if support > 0.9 {
                full.push(share);
            }
        }
    }
    let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
    assert!(
        thin.len() > 50 && full.len() > 50,
        "{} {}",
        thin.len(),
        full.len()
    );
    // Unweighted, a would give three quarters of the colour everywhere it sees.
    assert!(mean(&full) > 0.6, "a seen fully wins: {}", mean(&full));
    assert!(
        mean(&thin) < 0.3,
        "a seen through a corner loses: {}",
        mean(&thin)
    );
}

#[test]
fn any_number_of_threads_renders_the_same_image() {
    let (proxy, a, b) = desk_before_wall();
    let mut views = BackgroundViews::new(64, 48, proxy.clone(), 4, 0.0).expect("views");
    views.threads = 1;
    let photo = photograph(&proxy, &a);
    let frame = RgbaView::new("a", 64, 48, &photo).expect("view");
    assert!(
        views
            .offer(&a, &frame, &vec![0; 64 * 48], 0.0)
            .expect("offer")
    );
    // A region of a few rows, as the robot's is: fewer bands than threads in places.
    let only: Vec<u8> = (0..64 * 48)
        .map(|i| u8::from((9..19).contains(&(i / 64))))
        .collect();
    let alone = views.render(&b, None, Some(&only)).expect("render");
    let everywhere = views.render(&b, None, None).expect("render");
    assert!(alone.seen.iter().filter(|&&s| s > 0).count() > 300);
    // More threads than bands of rows: one per band, not one per request.
    for threads in [0, 2, 3, 7, 64, usize::MAX] {
        views.threads = threads;
        assert_eq!(
            views.render(&b, None, Some(&only)).expect("render"),
            alone,
            "{threads}"
        );
        assert_eq!(
            views.render(&b, None, None).expect("render"),
            everywhere,
            "{threads}"
        );
        assert_eq!(
            proxy.rect_map(&b, threads),
            proxy.rect_map(&b, 1),
            "{threads}"
        );
    }
}

#[test]
fn past_the_proxy_the_room_is_at_infinity() {
    // No proxy at all: a turning camera sees the same sky, painted by direction.
    let proxy = GeometricProxy::default();
    let sky = |cam: &PinholeCamera| -> Vec<u8> {
        let k = &cam.intrinsics;
        let mut out = Vec::new();
        for y in 0..k.height {
            for x in 0..k.width {
                let d = cam.ray(f64::from(x), f64::from(y));
                out.extend_from_slice(&[
                    (128.0 + 120.0 * d.y) as u8,
                    (128.0 + 120.0 * d.z) as u8,
                    60,
                    255,
                ]);
            }
        }
        out
    };
    let a = camera([0.0, 0.0, 1.0], [1.0, 0.0, 1.0]);
    let b = camera([0.0, 0.0, 1.0], [1.0, 0.1, 1.05]);
    let mut views = BackgroundViews::new(64, 48, proxy, 2, 0.0).expect("views");
    let photo = sky(&a);
    let f = RgbaView::new("a", 64, 48, &photo).expect("a");
    views.offer(&a, &f, &vec![0; 64 * 48], 0.0).expect("offer");
    let out = views.render(&b, None, None).expect("render");
    let truth = sky(&b);
    let seen: Vec<usize> = (0..64 * 48).filter(|&i| out.seen[i] > 0).collect();
    assert!(seen.len() > 64 * 48 / 2, "{}", seen.len());
    for i in seen {
        let e = (i32::from(out.rgba[i * 4]) - i32::from(truth[i * 4])).abs();
        assert!(e <= 2, "pixel {i}: {e}");
    }
}

#[test]
fn covered_pixels_are_not_used_and_the_nearer_view_wins() {
    let proxy = wall();
    let a = camera([1.5, -0.3, 1.0], [0.0, 0.0, 1.0]);
    let b = camera([1.5, 0.3, 1.0], [0.0, 0.0, 1.0]);
    let target = camera([1.5, 0.25, 1.0], [0.0, 0.0, 1.0]);
    let mut views = BackgroundViews::new(64, 48, proxy.clone(), 4, 0.0).expect("views");
    // a's picture is wrong (a lighting change: the room, red and darker), b's right.
    let wrong: Vec<u8> = photograph(&proxy, &a)
        .chunks_exact(4)
        .flat_map(|p| [p[0].saturating_add(80), p[1] / 2, p[2] / 2, 255])
        .collect();
    let right = photograph(&proxy, &b);
    let fa = RgbaView::new("a", 64, 48, &wrong).expect("a");
    let fb = RgbaView::new("b", 64, 48, &right).expect("b");
    assert!(views.offer(&a, &fa, &vec![0; 64 * 48], 0.0).expect("a"));
    assert!(views.offer(&b, &fb, &vec![0; 64 * 48], 1.0).expect("b"));
    assert_eq!(views.len(), 2);
    let out = views.render(&target, None, None).expect("render");
    let truth = photograph(&proxy, &target);
    let centre = (24 * 64 + 32) * 4;
    let err = (i32::from(out.rgba[centre]) - i32::from(truth[centre])).abs();
    assert!(err < 25, "b (3 deg away) outweighs a (20 deg away): {err}");
    // Covered everywhere: a view that may not be used adds nothing.
    let mut only_covered = BackgroundViews::new(64, 48, proxy, 4, 0.0).expect("views");
    assert!(
        only_covered
            .offer(&a, &fa, &vec![1; 64 * 48], 0.0)
            .expect("offer"),
        "kept: the first view, even with nothing usable"
    );
    assert_eq!(only_covered.blank(), 0, "covered is not blank");
    let out = only_covered.render(&target, None, None).expect("render");
    assert!(out.seen.iter().all(|&s| s == 0));
}

#[test]
fn views_are_kept_by_separation_and_bad_sizes_are_refused() {
    let proxy = wall();
    let mut views =
        BackgroundViews::new(64, 48, proxy.clone(), 2, 5f64.to_radians()).expect("views");
    let photo: Vec<u8> = (0..64 * 48 * 4).map(|i| (i % 251) as u8).collect();
    let f = RgbaView::new("f", 64, 48, &photo).expect("f");
    let free = vec![0u8; 64 * 48];
    let a = camera([1.5, 0.0, 1.0], [0.0, 0.0, 1.0]);
    let near = camera([1.5, 0.0, 1.0], [0.0, 0.05, 1.0]);
    let far = camera([1.5, 0.0, 1.0], [0.0, 0.5, 1.0]);
    let farther = camera([1.5, 0.0, 1.0], [0.0, -0.5, 1.0]);
    assert!(views.offer(&a, &f, &free, 0.0).expect("a"));
    assert!(
        !views.offer(&near, &f, &free, 0.1).expect("near"),
        "2 deg away"
    );
    assert!(views.offer(&far, &f, &free, 0.2).expect("far"));
    assert!(views.offer(&farther, &f, &free, 0.3).expect("farther"));
    assert_eq!(views.len(), 2, "the oldest went");
    assert_eq!(views.times(), vec![0.2, 0.3]);
    assert_eq!(views.offered(), 4);
    assert!(views.nearest_angle(&a).expect("angle") > 0.3);
    // A pinned view stays when the others come and go.
    let mut pinned =
        BackgroundViews::new(64, 48, proxy.clone(), 2, 5f64.to_radians()).expect("views");
    pinned.set_photograph(&a, &f, -1.0).expect("pinned");
    for (i, cam) in [&far, &farther, &near].into_iter().enumerate() {
        pinned.offer(cam, &f, &free, i as f64).expect("offer");
    }
    assert_eq!(pinned.times(), vec![-1.0, 1.0]);
    // A new photograph replaces the old one, wherever it was taken.
    pinned.set_photograph(&far, &f, -2.0).expect("again");
    assert_eq!(pinned.times(), vec![1.0, -2.0]);
    let mut bad = a;
    bad.world_from_camera.translation.vector.x = f64::NAN;
    assert!(pinned.offer(&bad, &f, &free, 5.0).is_err());
    assert!(pinned.set_photograph(&bad, &f, 5.0).is_err());
    let small = RgbaView::new("s", 32, 24, &photo[..32 * 24 * 4]).expect("s");
    assert!(views.offer(&a, &small, &free, 0.4).is_err());
    assert!(
        views
            .render(
                &camera([1.0, 0.0, 1.0], [0.0, 0.0, 1.0]),
                Some(vec![0u8; 3]),
                None
            )
            .is_err()
    );
    assert!(BackgroundViews::new(64, 48, proxy.clone(), 0, 0.0).is_err());
    assert!(BackgroundViews::new(64, 48, proxy, 2, f64::NAN).is_err());
}

#[test]
fn a_blank_frame_is_not_a_view() {
    // The live preview's first frame is black (the simulated camera has not rendered yet):
    // kept as a view, it darkened H by half wherever Alice looked back the same way.
    let mut views = BackgroundViews::new(64, 48, wall(), 4, 0.0).expect("views");
    let cam = camera([1.5, 0.0, 1.0], [0.0, 0.0, 1.0]);
    let free = vec![0u8; 64 * 48];
    let black = vec![0u8; 64 * 48 * 4];
    let f = RgbaView::new("black", 64, 48, &black).expect("f");
    assert!(!views.offer(&cam, &f, &free, 0.0).expect("offered"));
    // One colour with a sensor's noise (σ 1.5 levels, as the simulated camera adds) is as
    // blank; covered pixels do not count.
    let mut rng = crate::rng::Rng::stream(1, 2);
    let mut grey: Vec<u8> = (0..64 * 48 * 4)
        .map(|_| (128.0 + 1.5 * rng.gaussian()).round() as u8)
        .collect();
    grey[4 * 100] = 0;
    let mut covered = vec![0u8; 64 * 48];
    covered[100] = 1;
    let f = RgbaView::new("grey", 64, 48, &grey).expect("f");
    assert!(!views.offer(&cam, &f, &covered, 0.1).expect("offered"));
    assert_eq!((views.len(), views.offered(), views.blank()), (0, 2, 2));
    // The room is a view.
    let room = photograph(&wall(), &cam);
    let f = RgbaView::new("room", 64, 48, &room).expect("f");
    assert!(views.offer(&cam, &f, &free, 0.2).expect("offered"));
    assert_eq!(views.blank(), 2);
}
