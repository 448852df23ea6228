//! A small glTF 2.0 writer for tests: meshes, materials, nodes, one buffer, written as a
//! `.gltf` with a data URI, a `.gltf` with a `.bin` beside it, or a `.glb`. It shares no
//! code with the loader (`src/scene/gltf.rs`): it follows the glTF 2.0 specification.

use base64::Engine as _;
use serde_json::{Value, json};

#[derive(Default)]
pub struct GltfWriter {
    bin: Vec<u8>,
    pub buffer_views: Vec<Value>,
    pub accessors: Vec<Value>,
    pub meshes: Vec<Value>,
    pub materials: Vec<Value>,
    pub nodes: Vec<Value>,
    pub cameras: Vec<Value>,
    pub lights: Vec<Value>,
    /// The scene's root nodes.
    pub roots: Vec<usize>,
    /// Top-level keys added to the JSON as they are (`extensionsRequired`, ...).
    pub extra: Vec<(String, Value)>,
}

impl GltfWriter {
    fn push_view(&mut self, bytes: &[u8], target: u32) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.buffer_views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": bytes.len(), "target": target}));
        self.buffer_views.len() - 1
    }

    /// A VEC3 FLOAT accessor with the min and max the specification asks of POSITION.
    pub fn positions(&mut self, points: &[[f32; 3]]) -> usize {
        let bytes: Vec<u8> = points.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
        let view = self.push_view(&bytes, 34962);
        let bound = |pick: fn(f32, f32) -> f32| {
            (0..3).map(|c| points.iter().map(|p| p[c]).fold(points[0][c], pick)).collect::<Vec<_>>()
        };
        self.accessors.push(json!({
            "bufferView": view, "componentType": 5126, "count": points.len(), "type": "VEC3",
            "min": bound(f32::min), "max": bound(f32::max),
        }));
        self.accessors.len() - 1
    }

    /// A SCALAR UNSIGNED_SHORT (5123) or UNSIGNED_INT (5125) index accessor.
    pub fn indices(&mut self, indices: &[u32], component: u32) -> usize {
        let bytes: Vec<u8> = match component {
            5123 => indices.iter().flat_map(|&i| (i as u16).to_le_bytes()).collect(),
            _ => indices.iter().flat_map(|&i| i.to_le_bytes()).collect(),
        };
        let view = self.push_view(&bytes, 34963);
        self.accessors
            .push(json!({"bufferView": view, "componentType": component, "count": indices.len(), "type": "SCALAR"}));
        self.accessors.len() - 1
    }

    pub fn material(&mut self, material: Value) -> usize {
        self.materials.push(material);
        self.materials.len() - 1
    }

    /// A mesh of one triangle primitive; `indices` None writes a non-indexed one.
    pub fn mesh(&mut self, points: &[[f32; 3]], indices: Option<&[u32]>, material: Option<usize>) -> usize {
        let position = self.positions(points);
        let mut primitive = json!({"attributes": {"POSITION": position}});
        if let Some(indices) = indices {
            primitive["indices"] = json!(self.indices(indices, 5123));
        }
        if let Some(m) = material {
            primitive["material"] = json!(m);
        }
        self.meshes.push(json!({"primitives": [primitive]}));
        self.meshes.len() - 1
    }

    /// Adds a node and returns its index; `root` puts it in the scene.
    pub fn node(&mut self, node: Value, root: bool) -> usize {
        self.nodes.push(node);
        let index = self.nodes.len() - 1;
        if root {
            self.roots.push(index);
        }
        index
    }

    fn document(&self, buffer: Value) -> Value {
        let mut doc = json!({
            "asset": {"version": "2.0", "generator": "firstshot tests"},
            "scene": 0,
            "scenes": [{"nodes": self.roots}],
            "nodes": self.nodes,
            "meshes": self.meshes,
            "accessors": self.accessors,
            "bufferViews": self.buffer_views,
            "buffers": [buffer],
        });
        if !self.materials.is_empty() {
            doc["materials"] = json!(self.materials);
        }
        if !self.cameras.is_empty() {
            doc["cameras"] = json!(self.cameras);
        }
        let mut used: Vec<&str> = Vec::new();
        if !self.lights.is_empty() {
            doc["extensions"] = json!({"KHR_lights_punctual": {"lights": self.lights}});
            used.push("KHR_lights_punctual");
        }
        if self.materials.iter().any(|m| m.pointer("/extensions/KHR_materials_emissive_strength").is_some()) {
            used.push("KHR_materials_emissive_strength");
        }
        if !used.is_empty() {
            doc["extensionsUsed"] = json!(used);
        }
        for (key, value) in &self.extra {
            doc[key] = value.clone();
        }
        doc
    }

    /// A `.gltf` whose buffer is a base64 data URI.
    pub fn gltf_embedded(&self) -> String {
        let uri = format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&self.bin)
        );
        self.document(json!({"byteLength": self.bin.len(), "uri": uri})).to_string()
    }

    /// A `.gltf` naming `bin_name` beside it, and the bytes of that file.
    pub fn gltf_with_bin(&self, bin_name: &str) -> (String, Vec<u8>) {
        (self.document(json!({"byteLength": self.bin.len(), "uri": bin_name})).to_string(), self.bin.clone())
    }

    /// A binary `.glb`: header, JSON chunk (space-padded), BIN chunk (zero-padded).
    pub fn glb(&self) -> Vec<u8> {
        let mut json = self.document(json!({"byteLength": self.bin.len()})).to_string().into_bytes();
        while !json.len().is_multiple_of(4) {
            json.push(b' ');
        }
        let mut bin = self.bin.clone();
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let total = 12 + 8 + json.len() + 8 + bin.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(json.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&json);
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
        out
    }
}
