//! Binary glTF 2.0 (`.glb`) scenes: the surfaces (positions, normals, vertex colours, indices)
//! and the radiograph as a textured grid, under a root node that turns `table` (Z up) into
//! glTF's Y up.

use crate::scene::Scene;
use crate::FileError;
use serde_json::{json, Value};
use std::io::Write;
use std::path::Path;

const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const FLOAT: u32 = 5126;
const UNSIGNED_BYTE: u32 = 5121;
const UNSIGNED_INT: u32 = 5125;

#[derive(Default)]
struct Builder {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Builder {
    fn view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        self.view_with(target, |bin| bin.extend_from_slice(bytes))
    }
    /// A buffer view of the bytes `fill` appends to the binary buffer (written in place: a
    /// full-body surface's arrays are tens of MB).
    fn view_with(&mut self, target: Option<u32>, fill: impl FnOnce(&mut Vec<u8>)) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let start = self.bin.len();
        fill(&mut self.bin);
        let mut v = json!({"buffer": 0, "byteOffset": start, "byteLength": self.bin.len() - start});
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        self.views.push(v);
        self.views.len() - 1
    }
    fn accessor(
        &mut self,
        fill: impl FnOnce(&mut Vec<u8>),
        target: u32,
        component: u32,
        kind: &str,
        count: usize,
        extra: Value,
    ) -> usize {
        let view = self.view_with(Some(target), fill);
        let mut a = json!({"bufferView": view, "componentType": component, "count": count, "type": kind});
        if let (Some(a), Some(e)) = (a.as_object_mut(), extra.as_object()) {
            for (k, v) in e {
                a.insert(k.clone(), v.clone());
            }
        }
        self.accessors.push(a);
        self.accessors.len() - 1
    }
    fn vec3(&mut self, data: &[[f32; 3]], bounds: bool) -> usize {
        let extra = if bounds {
            let mut lo = [f32::INFINITY; 3];
            let mut hi = [f32::NEG_INFINITY; 3];
            for p in data {
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
            json!({"min": lo, "max": hi})
        } else {
            json!({})
        };
        self.accessor(|bin| put_le(bin, data, f32::to_le_bytes), ARRAY_BUFFER, FLOAT, "VEC3", data.len(), extra)
    }
    fn indices(&mut self, tris: &[[u32; 3]]) -> usize {
        self.accessor(
            |bin| put_le(bin, tris, u32::to_le_bytes),
            ELEMENT_ARRAY_BUFFER,
            UNSIGNED_INT,
            "SCALAR",
            tris.len() * 3,
            json!({}),
        )
    }
}

/// Appends each number of `data`, in order, as its 4 little-endian bytes (`le`).
fn put_le<T: Copy, const N: usize>(bin: &mut Vec<u8>, data: &[[T; N]], le: fn(T) -> [u8; 4]) {
    bin.reserve(data.len() * N * 4);
    for a in data {
        for &v in a {
            bin.extend_from_slice(&le(v));
        }
    }
}

/// The glTF document's arrays, filled surface by surface.
#[derive(Default)]
struct Doc {
    meshes: Vec<Value>,
    materials: Vec<Value>,
    nodes: Vec<Value>,
    images: Vec<Value>,
    textures: Vec<Value>,
    samplers: Vec<Value>,
}

impl Doc {
    /// A surface: its mesh (positions, normals and colours when it has them), a material with
    /// its transparency, and a node. Empty surfaces are left out.
    fn surface(&mut self, b: &mut Builder, s: &crate::scene::Surface<'_>) {
        let m = s.mesh;
        if m.triangles.is_empty() || m.positions.is_empty() {
            return;
        }
        let mut attrs = json!({"POSITION": b.vec3(&m.positions, true)});
        if m.normals.len() == m.positions.len() {
            attrs["NORMAL"] = json!(b.vec3(&m.normals, false));
        }
        if m.colors.len() == m.positions.len() {
            let fill = |bin: &mut Vec<u8>| {
                bin.reserve(m.colors.len() * 4);
                for c in &m.colors {
                    bin.extend_from_slice(&[c[0], c[1], c[2], 255]);
                }
            };
            attrs["COLOR_0"] = json!(b.accessor(
                fill,
                ARRAY_BUFFER,
                UNSIGNED_BYTE,
                "VEC4",
                m.colors.len(),
                json!({"normalized": true})
            ));
        }
        let indices = b.indices(&m.triangles);
        let alpha = 1.0 - s.transparency.clamp(0.0, 1.0);
        self.materials.push(json!({
            "name": s.name,
            "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, alpha], "metallicFactor": 0.0, "roughnessFactor": 0.9},
            "alphaMode": if alpha < 1.0 { "BLEND" } else { "OPAQUE" },
            "doubleSided": true
        }));
        self.meshes.push(json!({"name": s.name, "primitives": [{"attributes": attrs, "indices": indices, "material": self.materials.len() - 1}]}));
        self.nodes.push(json!({"name": s.name, "mesh": self.meshes.len() - 1}));
    }

    /// The radiograph's plane, textured with its PNG.
    fn plane(&mut self, b: &mut Builder, p: &crate::scene::TexturedPlane) {
        let pos = b.vec3(&p.positions, true);
        // glTF's texture origin is the image's top-left; the plane's is bottom-left.
        let uv: Vec<[f32; 2]> = p.uv.iter().map(|c| [c[0], 1.0 - c[1]]).collect();
        let tex =
            b.accessor(|bin| put_le(bin, &uv, f32::to_le_bytes), ARRAY_BUFFER, FLOAT, "VEC2", p.uv.len(), json!({}));
        let idx = b.indices(&p.triangles);
        let view = b.view(&p.png, None);
        self.images.push(json!({"bufferView": view, "mimeType": "image/png", "name": p.file_name}));
        self.samplers.push(json!({"magFilter": 9729, "minFilter": 9729, "wrapS": 33071, "wrapT": 33071}));
        self.textures.push(json!({"source": 0, "sampler": 0}));
        self.materials.push(json!({
            "name": "xray",
            "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0.0, "roughnessFactor": 1.0},
            "doubleSided": true
        }));
        self.meshes.push(json!({"name": "xray", "primitives": [{"attributes": {"POSITION": pos, "TEXCOORD_0": tex}, "indices": idx, "material": self.materials.len() - 1}]}));
        self.nodes.push(json!({"name": "xray", "mesh": self.meshes.len() - 1}));
    }

    /// The JSON document: every node under a `table` node that turns the table frame (z up)
    /// into glTF's (y up); the binary buffer padded to 4 bytes.
    fn json(mut self, b: &mut Builder) -> Value {
        let children: Vec<usize> = (0..self.nodes.len()).collect();
        self.nodes.push(json!({"name": "table", "rotation": [-std::f32::consts::FRAC_1_SQRT_2, 0.0, 0.0, std::f32::consts::FRAC_1_SQRT_2], "children": children}));
        let mut doc = json!({
            "asset": {"version": "2.0", "generator": "xsurf"},
            "scene": 0,
            "scenes": [{"name": "xsurf", "nodes": [self.nodes.len() - 1]}],
            "nodes": self.nodes,
        });
        if !self.meshes.is_empty() {
            while !b.bin.len().is_multiple_of(4) {
                b.bin.push(0);
            }
            doc["meshes"] = json!(self.meshes);
            doc["materials"] = json!(self.materials);
            doc["accessors"] = json!(b.accessors);
            doc["bufferViews"] = json!(b.views);
            doc["buffers"] = json!([{"byteLength": b.bin.len()}]);
        }
        if !self.images.is_empty() {
            doc["images"] = json!(self.images);
            doc["textures"] = json!(self.textures);
            doc["samplers"] = json!(self.samplers);
        }
        doc
    }
}

/// Writes the scene as a `.glb`.
pub fn write(w: &mut impl Write, scene: &Scene<'_>) -> std::io::Result<()> {
    let mut b = Builder::default();
    let mut doc = Doc::default();
    for s in &scene.surfaces {
        doc.surface(&mut b, s);
    }
    if let Some(p) = scene.plane.as_ref().filter(|p| !p.triangles.is_empty() && p.uv.len() == p.positions.len()) {
        doc.plane(&mut b, p);
    }
    let doc = doc.json(&mut b);
    let mut js = serde_json::to_vec(&doc).map_err(std::io::Error::other)?;
    while !js.len().is_multiple_of(4) {
        js.push(b' ');
    }
    let bin_chunk = if b.bin.is_empty() { 0 } else { 8 + b.bin.len() };
    let total = 12 + 8 + js.len() + bin_chunk;
    w.write_all(b"glTF")?;
    w.write_all(&2u32.to_le_bytes())?;
    w.write_all(&(total as u32).to_le_bytes())?;
    w.write_all(&(js.len() as u32).to_le_bytes())?;
    w.write_all(b"JSON")?;
    w.write_all(&js)?;
    if !b.bin.is_empty() {
        w.write_all(&(b.bin.len() as u32).to_le_bytes())?;
        w.write_all(b"BIN\0")?;
        w.write_all(&b.bin)?;
    }
    Ok(())
}

/// Writes the scene to a file atomically.
pub fn write_file(path: &Path, scene: &Scene<'_>) -> Result<(), FileError> {
    crate::write_atomic(path, |w| write(w, scene))
}

/// The JSON chunk of a `.glb` (for tests and tools). `None` if the header is not glTF 2.
pub fn read_json(glb: &[u8]) -> Option<Value> {
    if glb.len() < 20 || &glb[0..4] != b"glTF" || glb[4..8] != 2u32.to_le_bytes() || &glb[16..20] != b"JSON" {
        return None;
    }
    let n = u32::from_le_bytes([glb[12], glb[13], glb[14], glb[15]]) as usize;
    serde_json::from_slice(glb.get(20..20 + n)?).ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Surface, TexturedPlane};
    use xsurf_core::mesh::Mesh;

    #[test]
    fn glb_layout_and_json() {
        let mut m = Mesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.2]],
            normals: vec![],
            colors: vec![[255, 0, 0]; 3],
            triangles: vec![[0, 1, 2]],
        };
        m.compute_normals();
        let scene = Scene {
            surfaces: vec![Surface { name: "merged", mesh: &m, transparency: 0.4 }],
            plane: Some(TexturedPlane::quad([[0.0; 3]; 4], vec![1, 2, 3], "xray.png")),
        };
        let mut out = Vec::new();
        write(&mut out, &scene).unwrap();
        assert_eq!(out.len() % 4, 0);
        assert_eq!(u32::from_le_bytes([out[8], out[9], out[10], out[11]]) as usize, out.len());
        let j = read_json(&out).unwrap();
        assert_eq!(j["meshes"].as_array().unwrap().len(), 2);
        assert_eq!(j["accessors"][0]["max"][2], 0.2f32 as f64);
        assert_eq!(j["materials"][0]["alphaMode"], "BLEND");
        assert_eq!(j["images"][0]["mimeType"], "image/png");
    }
}
