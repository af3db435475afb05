//! Tests of [`super`] (calibrate).

use super::*;

/// A box of `size` (m) centred at `c`, as 12 triangles.
fn cuboid(c: [f64; 3], size: [f64; 3]) -> Vec<[Point3<f64>; 3]> {
    let v = |x: f64, y: f64, z: f64| {
        Point3::new(
            c[0] + x * size[0] / 2.0,
            c[1] + y * size[1] / 2.0,
            c[2] + z * size[2] / 2.0,
        )
    };
    let corners = [
        v(-1., -1., -1.),
        v(1., -1., -1.),
        v(1., 1., -1.),
        v(-1., 1., -1.),
        v(-1., -1., 1.),
        v(1., -1., 1.),
        v(1., 1., 1.),
        v(-1., 1., 1.),
    ];
    let faces = [
        [0, 1, 2, 3],
        [4, 5, 6, 7],
        [0, 1, 5, 4],
        [1, 2, 6, 5],
        [2, 3, 7, 6],
        [3, 0, 4, 7],
    ];
    faces
        .iter()
        .flat_map(|f| {
            [
                [corners[f[0]], corners[f[1]], corners[f[2]]],
                [corners[f[0]], corners[f[2]], corners[f[3]]],
            ]
        })
        .collect()
}

fn camera() -> (Intrinsics, Isometry3<f64>) {
    let k = Intrinsics::from_fov_y(50f64.to_radians(), 640, 480);
    // Looking along +x from 1.5 m back: optical z = world x, optical x = -world y,
    // optical y = -world z.
    let r = nalgebra::Rotation3::from_matrix_unchecked(nalgebra::Matrix3::new(
        0.0, -1.0, 0.0, 0.0, 0.0, -1.0, 1.0, 0.0, 0.0,
    ));
    let camera_from_base = Isometry3::from_parts(
        Translation3::new(0.0, 0.0, 1.5),
        UnitQuaternion::from_rotation_matrix(&r),
    );
    (k, camera_from_base)
}

/// Each triangle split in four, `levels` times (a mesh's small facets).
fn subdivided(triangles: &[[Point3<f64>; 3]], levels: usize) -> Vec<[Point3<f64>; 3]> {
    let mut out = triangles.to_vec();
    for _ in 0..levels {
        out = out
            .iter()
            .flat_map(|[a, b, c]| {
                let (ab, bc, ca) = (
                    nalgebra::center(a, b),
                    nalgebra::center(b, c),
                    nalgebra::center(c, a),
                );
                [[*a, ab, ca], [ab, *b, bc], [ca, bc, *c], [ab, bc, ca]]
            })
            .collect();
    }
    out
}

#[test]
fn a_distorted_lens_is_honoured() {
    let (k, truth) = camera();
    // A webcam's barrel distortion: the image's corners 13 % inwards.
    let lens = Distortion::PlumbBob([-0.25, 0.05, 0.0005, -0.0005, 0.0]);
    let frames: Vec<SilhouetteFrame> = [0.0f64, 0.2]
        .iter()
        .map(|&shift| {
            let mut boxes = cuboid([0.0, 0.0, 0.0], [0.2, 0.2, 0.6]);
            boxes.extend(cuboid([0.3, 0.4 + shift, 0.3], [0.2, 0.3, 0.1]));
            boxes.extend(cuboid([-0.3, -0.45, -0.3 + shift], [0.1, 0.1, 0.3]));
            let triangles = subdivided(&boxes, 3);
            let observed = rasterize(&triangles, &truth, &k, &lens);
            SilhouetteFrame {
                triangles,
                observed,
            }
        })
        .collect();
    let error = Isometry3::from_parts(
        Translation3::new(0.006, -0.005, 0.006),
        UnitQuaternion::from_scaled_axis(Vector3::new(0.01, -0.012, 0.005)),
    );
    let rough = error * truth;
    let off = |lens: Distortion| {
        let options = CalibrationOptions {
            distortion: lens,
            ..CalibrationOptions::default()
        };
        let r = calibrate(&frames, &k, &rough, &options, |_, _| {}).expect("fit");
        let d = r.camera_from_base * truth.inverse();
        (
            d.rotation.angle().to_degrees(),
            1e3 * d.translation.vector.norm(),
        )
    };
    let (deg, mm) = off(lens);
    let (deg_pinhole, mm_pinhole) = off(Distortion::None);
    eprintln!(
        "distortion honoured: {deg:.3} deg, {mm:.2} mm; ignored: {deg_pinhole:.3} deg, {mm_pinhole:.2} mm"
    );
    assert!(deg < 0.2 && mm < 3.0, "{deg:.3} deg, {mm:.2} mm");
    assert!(
        mm_pinhole > 3.0 * mm.max(1.0),
        "{mm_pinhole:.2} mm against {mm:.2} mm"
    );
}

#[test]
fn a_pose_is_fitted_to_image_edges_among_the_room_s() {
    let (k, truth) = camera();
    let (w, h) = (k.width as usize, k.height as usize);
    // The room's edges, which the robot does not explain: a tiled wall's grout lines every
    // 40 px, and a desk's edge across the frame.
    let room = |x: usize, y: usize| x.is_multiple_of(40) || y.is_multiple_of(40) || y == 400;
    // Each frame's silhouette and its edges: the robot's outline (one pixel wide, inside
    // it, as an edge detector puts it on one side) and the room's lines it does not hide.
    let (silhouettes, edges): (Vec<SilhouetteFrame>, Vec<SilhouetteFrame>) = [0.0f64, 0.2]
        .iter()
        .map(|&shift| {
            let mut boxes = cuboid([0.0, 0.0, 0.0], [0.2, 0.2, 0.6]);
            boxes.extend(cuboid([0.3, 0.4 + shift, 0.3], [0.2, 0.3, 0.1]));
            boxes.extend(cuboid([-0.3, -0.45, -0.3 + shift], [0.1, 0.1, 0.3]));
            let triangles = subdivided(&boxes, 1);
            let silhouette = rasterize(&triangles, &truth, &k, &Distortion::None);
            let outline = outline(&silhouette, w, h);
            let edges = (0..w * h)
                .map(|i| {
                    let room = silhouette[i] == 0 && room(i % w, i / w);
                    u8::from(outline[i] != 0 || room)
                })
                .collect();
            (
                SilhouetteFrame {
                    triangles: triangles.clone(),
                    observed: silhouette,
                },
                SilhouetteFrame {
                    triangles,
                    observed: edges,
                },
            )
        })
        .unzip();
    let error = Isometry3::from_parts(
        Translation3::new(0.006, -0.005, 0.006),
        UnitQuaternion::from_scaled_axis(Vector3::new(0.01, -0.012, 0.005)),
    );
    let rough = error * truth;
    let off = |frames: &[SilhouetteFrame], observed: Observed| {
        let options = CalibrationOptions {
            observed,
            ..CalibrationOptions::default()
        };
        let r = calibrate(frames, &k, &rough, &options, |_, _| {}).expect("fit");
        let d = r.camera_from_base * truth.inverse();
        (
            d.rotation.angle().to_degrees(),
            1e3 * d.translation.vector.norm(),
            reprojection_rms(frames, &r.camera_from_base, &truth, &k),
        )
    };
    let (deg, mm, px) = off(&edges, Observed::Edges);
    let (deg_s, mm_s, px_s) = off(&silhouettes, Observed::Silhouette);
    eprintln!(
        "from {:.2} deg, {:.1} mm ({:.1} px) off: edges {deg:.3} deg, {mm:.2} mm, {px:.2} px; silhouettes {deg_s:.3} deg, {mm_s:.2} mm, {px_s:.2} px",
        error.rotation.angle().to_degrees(),
        1e3 * error.translation.vector.norm(),
        reprojection_rms(&edges, &rough, &truth, &k),
    );
    // Measured: from 8.8 px off to 0.70 px (0.55 deg, 16 mm; the silhouettes 0.21 px,
    // 0.12 deg, 2.9 mm): edges place the outline to about a pixel, areas to a fraction of
    // one, and one view leaves a turn and a shift that look alike.
    assert!(px < 1.0, "{deg:.3} deg, {mm:.2} mm, {px:.2} px");
}

#[test]
fn an_empty_edge_map_is_refused_by_name() {
    let (k, truth) = camera();
    let frames = [SilhouetteFrame {
        triangles: cuboid([0.0, 0.0, 0.0], [0.2, 0.2, 0.6]),
        observed: vec![0; k.width as usize * k.height as usize],
    }];
    let options = CalibrationOptions {
        observed: Observed::Edges,
        ..CalibrationOptions::default()
    };
    let e = calibrate(&frames, &k, &truth, &options, |_, _| {}).expect_err("refused");
    assert!(
        e.to_string()
            .contains("frame 0: the observed edge map is empty"),
        "{e}"
    );
}

#[test]
fn clipping_keeps_what_is_above_the_table() {
    let unit = cuboid([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]);
    let area = |ts: &[[Point3<f64>; 3]]| -> f64 {
        ts.iter()
            .map(|t| 0.5 * (t[1] - t[0]).cross(&(t[2] - t[0])).norm())
            .sum()
    };
    // The unit cube from z = -0.5 to 0.5, cut at z = 0.25: the top face and a quarter of
    // each side are left (1 + 4 x 0.25 m^2).
    let kept = clip_below(&unit, 0.25);
    assert!((area(&kept) - 2.0).abs() < 1e-9, "{}", area(&kept));
    assert!(kept.iter().flatten().all(|p| p.z >= 0.25 - 1e-12));
    assert_eq!(clip_below(&unit, 1.0).len(), 0);
    assert_eq!(clip_below(&unit, -1.0), unit);
}

#[test]
fn the_distance_transform_is_exact() {
    let (w, h) = (7, 5);
    let mut seeds = vec![0u8; w * h];
    seeds[2 * w + 3] = 1;
    seeds[0] = 1;
    let d = distance_transform(&seeds, w, h);
    for y in 0..h {
        for x in 0..w {
            let a = ((x as f64 - 3.0).powi(2) + (y as f64 - 2.0).powi(2)).sqrt();
            let b = ((x * x + y * y) as f64).sqrt();
            assert!(
                (f64::from(d[y * w + x]) - a.min(b)).abs() < 1e-5,
                "({x}, {y})"
            );
        }
    }
    assert!(
        distance_transform(&[0; 4], 2, 2)
            .iter()
            .all(|v| v.is_infinite())
    );
}

#[test]
fn a_box_rasterises_where_it_projects() {
    let (k, pose) = camera();
    // A 0.4 m cube at 1.5 m: about 0.4 / 1.5 * fy = 34 px across.
    let mask = rasterize(
        &cuboid([0.0, 0.0, 0.0], [0.4, 0.4, 0.4]),
        &pose,
        &k,
        &Distortion::None,
    );
    let count = mask.iter().filter(|&&m| m != 0).count();
    let side = 0.4 / 1.3 * k.fy; // the near face at 1.3 m bounds it
    assert!(
        count as f64 > 0.8 * side * side && (count as f64) < 1.2 * side * side,
        "{count}"
    );
    // Centred.
    let (mut sx, mut sy) = (0.0, 0.0);
    for (i, &m) in mask.iter().enumerate() {
        if m != 0 {
            sx += (i % 640) as f64;
            sy += (i / 640) as f64;
        }
    }
    assert!((sx / count as f64 - k.cx).abs() < 1.0 && (sy / count as f64 - k.cy).abs() < 1.0);
    // Behind the camera: nothing.
    let behind = rasterize(
        &cuboid([-3.0, 0.0, 0.0], [0.4, 0.4, 0.4]),
        &pose,
        &k,
        &Distortion::None,
    );
    assert!(behind.iter().all(|&m| m == 0));
}

#[test]
fn the_pose_is_recovered_from_silhouettes() {
    let (k, truth) = camera();
    // Boxes at several depths seen in three configurations (the robot's joints move between
    // frames), filling a good part of the view as an arm does.
    let frames: Vec<SilhouetteFrame> = [0.0f64, 0.15, -0.2]
        .iter()
        .map(|&shift| {
            let mut triangles = cuboid([0.0, 0.0, 0.0], [0.2, 0.2, 0.6]);
            triangles.extend(cuboid([0.3, 0.25 + shift, 0.25], [0.2, 0.4, 0.1]));
            triangles.extend(cuboid([-0.3, -0.3, -0.2 + shift], [0.1, 0.1, 0.3]));
            triangles.extend(cuboid([0.5, -0.1 - shift, 0.3], [0.1, 0.3, 0.1]));
            let observed = rasterize(&triangles, &truth, &k, &Distortion::None);
            SilhouetteFrame {
                triangles,
                observed,
            }
        })
        .collect();
    // 2 degrees and 20 mm off.
    let error = Isometry3::from_parts(
        Translation3::new(0.012, -0.010, 0.012),
        UnitQuaternion::from_scaled_axis(Vector3::new(0.02, -0.025, 0.01)),
    );
    let rough = error * truth;
    let r = calibrate(
        &frames,
        &k,
        &rough,
        &CalibrationOptions::default(),
        |_, _| {},
    )
    .expect("fit");
    let d = r.camera_from_base * truth.inverse();
    let (deg, mm) = (
        d.rotation.angle().to_degrees(),
        1e3 * d.translation.vector.norm(),
    );
    eprintln!(
        "recovered to {deg:.3} deg, {mm:.2} mm; {} evaluations",
        r.evaluations
    );
    let px = reprojection_rms(&frames, &r.camera_from_base, &truth, &k);
    let px_rough = reprojection_rms(&frames, &rough, &truth, &k);
    eprintln!("the robot where the truth puts it to {px:.2} px RMS (rough: {px_rough:.1} px)");
    // Measured: 0.25 px RMS from 16.9 px; 0.061 deg, 1.86 mm (the pose is pinned down least
    // along the direction where a rotation and a sideways shift look alike).
    assert!(px < 0.35, "{px:.2} px: {r:?}");
    assert!(deg < 0.2 && mm < 3.0, "{deg:.3} deg, {mm:.2} mm: {r:?}");
    assert!(r.cost_px < r.rough_cost_px);
    // Bad input is refused by name.
    let empty = SilhouetteFrame {
        triangles: frames[0].triangles.clone(),
        observed: vec![0; frames[0].observed.len()],
    };
    let e = calibrate(
        &[empty],
        &k,
        &rough,
        &CalibrationOptions::default(),
        |_, _| {},
    )
    .expect_err("empty");
    assert!(e.to_string().contains("empty"), "{e}");
    assert!(calibrate(&[], &k, &rough, &CalibrationOptions::default(), |_, _| {}).is_err());
}
