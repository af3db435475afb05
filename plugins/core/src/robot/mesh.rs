//! Triangle meshes from STL, OBJ and glTF/GLB files, for the robot twin's link geometry.

use std::path::Path;

use nalgebra::{Matrix4, Point3, Vector3};

use crate::error::{Error, Result};

/// An indexed triangle mesh in the file's units times the URDF scale.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Per-vertex normals, when the file has them.
    pub normals: Option<Vec<[f32; 3]>>,
    /// Triangle list, three indices per triangle.
    pub indices: Vec<u32>,
}

impl TriMesh {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Axis-aligned bounds `(min, max)`, or `None` for an empty mesh.
    pub fn bounds(&self) -> Option<([f32; 3], [f32; 3])> {
        let first = *self.positions.first()?;
        Some(self.positions.iter().fold((first, first), |(lo, hi), p| {
            (
                [lo[0].min(p[0]), lo[1].min(p[1]), lo[2].min(p[2])],
                [hi[0].max(p[0]), hi[1].max(p[1]), hi[2].max(p[2])],
            )
        }))
    }
}

/// The mesh formats Avatarm loads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshFormat {
    /// STL, ASCII or binary.
    Stl,
    /// Wavefront OBJ.
    Obj,
    /// glTF 2.0, `.gltf` or `.glb`.
    Gltf,
}

impl MeshFormat {
    /// The format of a file by its extension, or an error naming the file and suggesting a fix.
    pub fn of(path: &Path) -> Result<Self> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        match ext.as_str() {
            "stl" => Ok(Self::Stl),
            "obj" => Ok(Self::Obj),
            "gltf" | "glb" => Ok(Self::Gltf),
            _ => Err(Error::UnsupportedMesh {
                path: path.to_owned(),
                extension: ext,
                stem: path
                    .file_stem()
                    .and_then(|s| s.to_str())
                    .unwrap_or("mesh")
                    .to_owned(),
            }),
        }
    }
}

/// Loads a mesh file and applies a per-axis scale.
pub fn load_mesh(path: &Path, scale: &Vector3<f64>) -> Result<TriMesh> {
    let bad = |message: String| Error::BadMesh {
        path: path.to_owned(),
        message,
    };
    let mut mesh = match MeshFormat::of(path)? {
        MeshFormat::Stl => {
            let mut file = std::fs::File::open(path).map_err(|source| Error::Io {
                path: path.to_owned(),
                source,
            })?;
            let stl = stl_io::read_stl(&mut file).map_err(|e| bad(e.to_string()))?;
            let positions = stl.vertices.iter().map(|v| [v[0], v[1], v[2]]).collect();
            let mut indices = Vec::with_capacity(stl.faces.len() * 3);
            for f in &stl.faces {
                for &i in &f.vertices {
                    indices.push(u32::try_from(i).map_err(|_| bad("too many vertices".into()))?);
                }
            }
            TriMesh {
                positions,
                normals: None,
                indices,
            }
        }
        MeshFormat::Obj => {
            let options = tobj::LoadOptions {
                triangulate: true,
                single_index: true,
                ..Default::default()
            };
            let (models, _) = tobj::load_obj(path, &options).map_err(|e| bad(e.to_string()))?;
            let mut out = TriMesh::default();
            let mut normals = Vec::new();
            let mut all_have_normals = true;
            for m in models {
                let base = out.positions.len() as u32;
                let m = m.mesh;
                out.positions
                    .extend(m.positions.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
                if m.normals.len() == m.positions.len() {
                    normals.extend(m.normals.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
                } else {
                    all_have_normals = false;
                }
                out.indices.extend(m.indices.iter().map(|i| i + base));
            }
            out.normals = all_have_normals.then_some(normals);
            out
        }
        MeshFormat::Gltf => load_gltf(path)?,
    };
    if mesh
        .indices
        .iter()
        .any(|&i| i as usize >= mesh.positions.len())
    {
        return Err(bad("a triangle index is out of range".into()));
    }
    if mesh.positions.iter().flatten().any(|v| !v.is_finite()) {
        return Err(bad("a vertex position is not finite".into()));
    }
    let s = scale.map(|v| v as f32);
    for p in &mut mesh.positions {
        *p = [p[0] * s.x, p[1] * s.y, p[2] * s.z];
    }
    if let Some(normals) = &mut mesh.normals {
        // Normals transform by the inverse scale, then renormalise.
        for n in normals.iter_mut() {
            let v = Vector3::new(n[0] / s.x, n[1] / s.y, n[2] / s.z);
            let v = v.try_normalize(1e-12).unwrap_or(Vector3::z());
            *n = [v.x, v.y, v.z];
        }
    }
    Ok(mesh)
}

fn load_gltf(path: &Path) -> Result<TriMesh> {
    let (doc, buffers, _) = gltf::import(path).map_err(|e| Error::BadMesh {
        path: path.to_owned(),
        message: e.to_string(),
    })?;
    let mut out = TriMesh::default();
    let mut normals = Vec::new();
    let mut all_have_normals = true;
    let scene = doc.default_scene().or_else(|| doc.scenes().next());
    let mut stack: Vec<(gltf::Node<'_>, Matrix4<f32>)> = scene
        .map(|s| s.nodes().map(|n| (n, Matrix4::identity())).collect())
        .unwrap_or_default();
    while let Some((node, parent)) = stack.pop() {
        let local = Matrix4::from(node.transform().matrix());
        let world = parent * local;
        if let Some(mesh) = node.mesh() {
            let normal_matrix = world
                .fixed_view::<3, 3>(0, 0)
                .try_inverse()
                .map(|m| m.transpose())
                .unwrap_or_else(nalgebra::Matrix3::identity);
            for prim in mesh.primitives() {
                if prim.mode() != gltf::mesh::Mode::Triangles {
                    continue;
                }
                let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
                let Some(positions) = reader.read_positions() else {
                    continue;
                };
                let base = out.positions.len() as u32;
                let count_before = out.positions.len();
                out.positions.extend(positions.map(|p| {
                    let v = world.transform_point(&Point3::new(p[0], p[1], p[2]));
                    [v.x, v.y, v.z]
                }));
                let added = out.positions.len() - count_before;
                match reader.read_normals() {
                    Some(ns) => normals.extend(ns.map(|n| {
                        let v = (normal_matrix * Vector3::new(n[0], n[1], n[2]))
                            .try_normalize(1e-12)
                            .unwrap_or(Vector3::z());
                        [v.x, v.y, v.z]
                    })),
                    None => all_have_normals = false,
                }
                match reader.read_indices() {
                    Some(idx) => out.indices.extend(idx.into_u32().map(|i| i + base)),
                    None => out.indices.extend((0..added as u32).map(|i| i + base)),
                }
            }
        }
        stack.extend(node.children().map(|c| (c, world)));
    }
    out.normals = (all_have_normals && normals.len() == out.positions.len()).then_some(normals);
    Ok(out)
}

#[cfg(test)]
mod tests {
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

    #[test]
    fn unsupported_and_broken_files_name_the_file() {
        let dae = tmp("arm.dae");
        std::fs::write(&dae, "<COLLADA/>").unwrap();
        let e = load_mesh(&dae, &Vector3::repeat(1.0))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("arm.dae") && e.contains("collision") && e.contains("glb"),
            "{e}"
        );
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
}
