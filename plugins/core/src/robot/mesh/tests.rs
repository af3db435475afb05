//! Tests of [`super`] (mesh).

use super::*;

fn tmp(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("avatarm_mesh_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn loads_stl_and_obj_with_scale() {
    let stl = tmp("tri.stl");
    std::fs::write(
        &stl,
        "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid t\n",
    )
    .unwrap();
    let m = load_mesh(&stl, &Vector3::new(2.0, 2.0, 2.0)).unwrap();
    assert_eq!(m.triangle_count(), 1);
    assert_eq!(m.bounds().unwrap().1, [2.0, 2.0, 0.0]);

    let obj = tmp("quad.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n").unwrap();
    let m = load_mesh(&obj, &Vector3::repeat(1.0)).unwrap();
    assert_eq!(m.triangle_count(), 2);
}

#[test]
fn loads_a_minimal_gltf() {
    // One triangle; buffer embedded as a data URI.
    let data: Vec<u8> = [0f32, 0., 0., 1., 0., 0., 0., 1., 0.]
        .iter()
        .flat_map(|f| f.to_le_bytes())
        .collect();
    let b64 = base64_encode(&data);
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],
        "nodes":[{{"mesh":0,"translation":[0,0,1]}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}],
        "bufferViews":[{{"buffer":0,"byteLength":36}}],
        "buffers":[{{"byteLength":36,"uri":"data:application/octet-stream;base64,{b64}"}}]}}"#
    );
    let path = tmp("tri.gltf");
    std::fs::write(&path, json).unwrap();
    let m = load_mesh(&path, &Vector3::repeat(1.0)).unwrap();
    assert_eq!(m.triangle_count(), 1);
    assert_eq!(m.positions[1], [1.0, 0.0, 1.0]);
}

/// Two triangles in millimetres, Y up, the second moved by its node's `<translate>`; one
/// red and one blue material.
fn collada(up: &str) -> String {
    let geometry = |id: &str, material: &str| {
        format!(
            r##"<geometry id="{id}"><mesh>
  <source id="{id}-pos"><float_array id="{id}-arr" count="9">0 0 0 100 0 0 0 100 0</float_array>
<technique_common><accessor source="#{id}-arr" count="3" stride="3"><param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/></accessor></technique_common></source>
  <vertices id="{id}-vtx"><input semantic="POSITION" source="#{id}-pos"/></vertices>
  <triangles material="{material}" count="1"><input semantic="VERTEX" source="#{id}-vtx" offset="0"/><p>0 1 2</p></triangles>
</mesh></geometry>"##
        )
    };
    let effect = |id: &str, rgba: &str| {
        format!(
            r#"<effect id="{id}-fx"><profile_COMMON><technique sid="common"><phong><diffuse><color>{rgba}</color></diffuse></phong></technique></profile_COMMON></effect>"#
        )
    };
    let instance = |url: &str, symbol: &str, target: &str| {
        format!(
            r##"<instance_geometry url="#{url}"><bind_material><technique_common><instance_material symbol="{symbol}" target="#{target}"/></technique_common></bind_material></instance_geometry>"##
        )
    };
    format!(
        r##"<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
<asset><unit name="millimeter" meter="0.001"/><up_axis>{up}</up_axis></asset>
<library_effects>{}{}</library_effects>
<library_materials><material id="red" name="red"><instance_effect url="#red-fx"/></material><material id="blue" name="blue"><instance_effect url="#blue-fx"/></material></library_materials>
<library_geometries>{}{}</library_geometries>
<library_visual_scenes><visual_scene id="scene">
  <node id="a">{}</node>
  <node id="b"><translate>0 0 50</translate>{}</node>
  <node id="c"><rotate>0 0 1 90</rotate><node id="c1"><translate>200 0 0</translate>{}</node></node>
</visual_scene></library_visual_scenes>
<scene><instance_visual_scene url="#scene"/></scene>
</COLLADA>"##,
        effect("red", "1 0 0 1"),
        effect("blue", "0 0 1 1"),
        geometry("tri_a", "ma"),
        geometry("tri_b", "mb"),
        instance("tri_a", "ma", "red"),
        instance("tri_b", "mb", "blue"),
        instance("tri_a", "ma", "red"),
    )
}

fn close(a: [f32; 3], b: [f32; 3]) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-6)
}

#[test]
fn collada_units_up_axis_nodes_and_materials() {
    // Upper-case extension, as the Sawyer's meshes are.
    let path = tmp("Y_UP.DAE");
    std::fs::write(&path, collada("Y_UP")).unwrap();
    let m = load_mesh(&path, &Vector3::repeat(1.0)).unwrap();
    // tri_a twice (nodes a and c1), tri_b once.
    assert_eq!(m.triangle_count(), 3);
    let find = |p: [f32; 3]| m.positions.iter().position(|q| close(*q, p));
    // Millimetres to metres; Y up turned to Z up: (x, y, z) -> (x, -z, y).
    let a1 = find([0.1, 0.0, 0.0]).expect("x vertex of a");
    let a2 = find([0.0, 0.0, 0.1]).expect("y vertex of a, now up");
    // Node b's <translate> 50 mm along its z, which is -y in Z-up.
    let b2 =
        find([0.0, -0.05, 0.1]).unwrap_or_else(|| panic!("y vertex of b in {:?}", m.positions));
    let colors = m.colors.as_ref().expect("material colours");
    assert_eq!(colors[a1], [1.0, 0.0, 0.0, 1.0]);
    assert_eq!(colors[a2], [1.0, 0.0, 0.0, 1.0]);
    assert_eq!(colors[b2], [0.0, 0.0, 1.0, 1.0]);

    let path = tmp("z_up.dae");
    std::fs::write(&path, collada("Z_UP")).unwrap();
    let m = load_mesh(&path, &Vector3::repeat(2.0)).unwrap();
    assert!(m.positions.iter().any(|p| close(*p, [0.0, 0.2, 0.0])));
    assert!(m.positions.iter().any(|p| close(*p, [0.0, 0.2, 0.1])));
    // Nested nodes compose parent-first: c1's 200 mm along x, then c's 90° about z.
    assert!(
        m.positions.iter().any(|p| close(*p, [0.0, 0.4, 0.0])),
        "{:?}",
        m.positions
    );

    let path = tmp("x_up.dae");
    std::fs::write(&path, collada("X_UP")).unwrap();
    let m = load_mesh(&path, &Vector3::repeat(1.0)).unwrap();
    // X up: (x, y, z) -> (-z, y, x): the x vertex of a points up, and b's origin (50 mm
    // along its z) goes to -x (Y up would put it at -y).
    assert!(m.positions.iter().any(|p| close(*p, [0.0, 0.0, 0.1])));
    assert!(m.positions.iter().any(|p| close(*p, [-0.05, 0.0, 0.0])));
    assert!(!m.positions.iter().any(|p| close(*p, [0.0, -0.05, 0.0])));

    let path = tmp("sideways.dae");
    std::fs::write(&path, collada("W_UP")).unwrap();
    let e = load_mesh(&path, &Vector3::repeat(1.0))
        .unwrap_err()
        .to_string();
    assert!(e.contains("sideways.dae") && e.contains("W_UP"), "{e}");
}

/// ../shared/cases/01: a binary STL whose header starts with `solid`.
#[test]
fn a_binary_stl_with_a_solid_header_is_binary() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/cases/01-binary-stl-solid-header/meshes/gripper_base.STL");
    let m = load_mesh(&path, &Vector3::repeat(1.0)).unwrap();
    assert_eq!(m.triangle_count(), 10);
    let (lo, hi) = m.bounds().unwrap();
    assert!(close(lo, [-0.032361, -0.038042, -0.05]), "{lo:?}");
    assert!(close(hi, [0.04, 0.038042, 0.05]), "{hi:?}");
}

/// ../shared/cases/03: an ASCII STL whose first line is a bare `solid` (no name, no trailing
/// space), 1010 bytes (not a binary STL's size), reads as ASCII; so does `solid ` with a
/// trailing space, and a file that is neither is refused naming what it is not.
#[test]
fn an_ascii_stl_with_a_bare_solid_line_is_ascii() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/cases/03-ascii-stl-unnamed-solid/meshes/spacer.stl");
    let m = load_mesh(&path, &Vector3::repeat(1.0)).unwrap();
    assert_eq!(m.triangle_count(), 4);
    let facet = "facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\n";
    for (name, head) in [
        ("bare_crlf.stl", "solid\r\n"),
        ("trailing_space.stl", "solid \n"),
        ("indented.stl", "  solid\n"),
    ] {
        let stl = tmp(name);
        std::fs::write(&stl, format!("{head}{facet}endsolid\n")).unwrap();
        let m = load_mesh(&stl, &Vector3::repeat(1.0)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(m.triangle_count(), 1, "{name}");
    }
    let junk = tmp("junk.stl");
    std::fs::write(&junk, "not a mesh at all\n").unwrap();
    let e = load_mesh(&junk, &Vector3::repeat(1.0))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("junk.stl") && e.contains("neither ASCII STL") && e.contains("binary STL"),
        "{e}"
    );
    assert_eq!(stl_kind(b"solidworks export"), StlKind::Neither);
}

#[test]
fn a_negative_scale_mirrors_with_outward_faces_and_zero_is_refused() {
    let stl = tmp("mirror.stl");
    std::fs::write(
        &stl,
        "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid t\n",
    )
    .unwrap();
    for scale in [
        Vector3::new(-1.0, 1.0, 1.0),
        Vector3::new(1.0, -2.0, -1.0),
        Vector3::new(-1.0, -1.0, -1.0),
    ] {
        let m = load_mesh(&stl, &scale).unwrap();
        let p = |i: usize| Vector3::from(m.positions[m.indices[i] as usize]);
        let face = (p(1) - p(0)).cross(&(p(2) - p(0)));
        // The facet's normal, transformed by the inverse scale.
        let n = Vector3::new(0.0, 0.0, 1.0 / scale.z as f32);
        assert!(
            face.dot(&n) > 0.0,
            "scale {scale:?}: face {face:?} against {n:?}"
        );
        if let Some(normals) = &m.normals {
            assert!(Vector3::from(normals[0]).dot(&n) > 0.0);
        }
    }
    // A facet normal of 0 0 0 (as many exporters write) is recomputed, not used as +z.
    let zero = tmp("zero_normal.stl");
    std::fs::write(
        &zero,
        "solid t\nfacet normal 0 0 0\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid t\n",
    )
    .unwrap();
    assert_eq!(
        load_mesh(&zero, &Vector3::repeat(1.0)).unwrap().normals,
        None
    );
    for scale in [
        Vector3::new(0.0, 1.0, 1.0),
        Vector3::new(1.0, f64::NAN, 1.0),
    ] {
        let e = load_mesh(&stl, &scale).unwrap_err().to_string();
        assert!(e.contains("mirror.stl") && e.contains("scale"), "{e}");
    }
}

#[test]
fn simplification_keeps_the_shape_with_fewer_triangles() {
    // A 16 x 16 grid of unwelded quads (each triangle its own vertices, as Collada gives).
    let mut m = TriMesh::default();
    for i in 0..16 {
        for j in 0..16 {
            let (x, y) = (i as f32 / 16.0, j as f32 / 16.0);
            let d = 1.0 / 16.0;
            for tri in [
                [[x, y], [x + d, y], [x + d, y + d]],
                [[x, y], [x + d, y + d], [x, y + d]],
            ] {
                for [px, py] in tri {
                    m.indices.push(m.positions.len() as u32);
                    m.positions.push([px, py, 0.0]);
                }
            }
        }
    }
    assert_eq!(m.triangle_count(), 512);
    let s = m.simplified(0.1);
    assert!(
        s.triangle_count() <= 52 && s.triangle_count() >= 2,
        "{}",
        s.triangle_count()
    );
    // A flat square stays the unit square.
    assert_eq!(s.bounds(), m.bounds());
    let area: f32 = s
        .indices
        .chunks_exact(3)
        .map(|t| {
            let p = |k: usize| Vector3::from(s.positions[t[k] as usize]);
            (p(1) - p(0)).cross(&(p(2) - p(0))).norm() / 2.0
        })
        .sum();
    assert!((area - 1.0).abs() < 1e-4, "area {area}");
    assert_eq!(m.simplified(1.0), m);
}

#[test]
fn unsupported_and_broken_files_name_the_file() {
    let ply = tmp("arm.ply");
    std::fs::write(&ply, "ply\n").unwrap();
    let e = load_mesh(&ply, &Vector3::repeat(1.0))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("arm.ply") && e.contains("collision") && e.contains("glb"),
        "{e}"
    );
    let dae = tmp("empty.dae");
    std::fs::write(&dae, "<COLLADA/>").unwrap();
    let e = load_mesh(&dae, &Vector3::repeat(1.0))
        .unwrap_err()
        .to_string();
    assert!(e.contains("empty.dae"), "{e}");
    let broken = tmp("broken.obj");
    std::fs::write(&broken, "f 1 2 3\n").unwrap();
    let e = load_mesh(&broken, &Vector3::repeat(1.0))
        .unwrap_err()
        .to_string();
    assert!(e.contains("broken.obj"), "{e}");
}

fn base64_encode(data: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in data.chunks(3) {
        let n = (u32::from(c[0]) << 16)
            | (u32::from(*c.get(1).unwrap_or(&0)) << 8)
            | u32::from(*c.get(2).unwrap_or(&0));
        for k in 0..4 {
            if k <= c.len() {
                s.push(T[(n >> (18 - 6 * k)) as usize & 63] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}
