//! Binary little-endian PLY: `float x y z`, optional `uchar red green blue`, faces as
//! `list uchar int vertex_indices` (the spec's Files section).

use crate::FileError;
use std::io::{BufRead, Write};
use std::path::Path;
use xsurf_core::mesh::Mesh;

/// Why a PLY file cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum PlyError {
    /// I/O failure.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// The header is not one we write.
    #[error("PLY header: {0}")]
    Header(String),
    /// A face refers to a vertex that does not exist.
    #[error("PLY face {face} refers to vertex {index} of {vertices}")]
    BadIndex {
        /// Face number.
        face: usize,
        /// Index.
        index: i64,
        /// Vertex count.
        vertices: usize,
    },
    /// The file ends early.
    #[error("PLY body ends early at byte {offset} (in {element} {index})")]
    Truncated {
        /// Byte offset in the file.
        offset: u64,
        /// Element name.
        element: &'static str,
        /// Element index.
        index: usize,
    },
}

/// Writes a mesh (colours included when it has one per vertex).
pub fn write(w: &mut impl Write, mesh: &Mesh) -> std::io::Result<()> {
    let color = mesh.colors.len() == mesh.positions.len() && !mesh.positions.is_empty();
    writeln!(w, "ply\nformat binary_little_endian 1.0\ncomment xsurf surface, metres, frame table")?;
    writeln!(w, "element vertex {}\nproperty float x\nproperty float y\nproperty float z", mesh.positions.len())?;
    if color {
        writeln!(w, "property uchar red\nproperty uchar green\nproperty uchar blue")?;
    }
    writeln!(w, "element face {}\nproperty list uchar int vertex_indices\nend_header", mesh.triangles.len())?;
    let mut buf = Vec::with_capacity(mesh.positions.len() * 15 + mesh.triangles.len() * 13);
    for (i, p) in mesh.positions.iter().enumerate() {
        for v in p {
            buf.extend_from_slice(&v.to_le_bytes());
        }
        if color {
            buf.extend_from_slice(&mesh.colors[i]);
        }
    }
    for t in &mesh.triangles {
        buf.push(3);
        for &i in t {
            buf.extend_from_slice(&(i as i32).to_le_bytes());
        }
    }
    w.write_all(&buf)
}

/// Writes a mesh to a file atomically.
pub fn write_file(path: &Path, mesh: &Mesh) -> Result<(), FileError> {
    crate::write_atomic(path, |w| write(w, mesh))
}

/// Reads a PLY file of the layout [`write`] produces (used by tests and tools).
pub fn read(r: &mut impl BufRead) -> Result<Mesh, PlyError> {
    let mut header = Vec::new();
    let mut offset = 0u64;
    loop {
        let mut line = String::new();
        let n = r.read_line(&mut line)?;
        if n == 0 {
            return Err(PlyError::Header("no end_header".into()));
        }
        offset += n as u64;
        let line = line.trim_end().to_string();
        if line == "end_header" {
            break;
        }
        header.push(line);
    }
    if header.first().map(String::as_str) != Some("ply") {
        return Err(PlyError::Header("does not start with 'ply'".into()));
    }
    if !header.iter().any(|l| l == "format binary_little_endian 1.0") {
        return Err(PlyError::Header("not binary_little_endian 1.0".into()));
    }
    let count = |name: &str| -> Result<usize, PlyError> {
        header
            .iter()
            .find_map(|l| l.strip_prefix(&format!("element {name} ")))
            .ok_or_else(|| PlyError::Header(format!("no element {name}")))?
            .trim()
            .parse()
            .map_err(|_| PlyError::Header(format!("bad count for element {name}")))
    };
    let (nv, nf) = (count("vertex")?, count("face")?);
    let color = header.iter().any(|l| l == "property uchar red");
    let mut mesh = Mesh::default();
    let vsize = 12 + if color { 3 } else { 0 };
    let mut vb = vec![0u8; vsize];
    for i in 0..nv {
        r.read_exact(&mut vb).map_err(|_| PlyError::Truncated { offset, element: "vertex", index: i })?;
        offset += vsize as u64;
        let f = |k: usize| f32::from_le_bytes([vb[k], vb[k + 1], vb[k + 2], vb[k + 3]]);
        mesh.positions.push([f(0), f(4), f(8)]);
        if color {
            mesh.colors.push([vb[12], vb[13], vb[14]]);
        }
    }
    let mut fb = [0u8; 13];
    for i in 0..nf {
        r.read_exact(&mut fb).map_err(|_| PlyError::Truncated { offset, element: "face", index: i })?;
        offset += 13;
        if fb[0] != 3 {
            return Err(PlyError::Header(format!("face {i} has {} vertices, expected 3", fb[0])));
        }
        let mut t = [0u32; 3];
        for k in 0..3 {
            let v = i32::from_le_bytes([fb[1 + 4 * k], fb[2 + 4 * k], fb[3 + 4 * k], fb[4 + 4 * k]]);
            if v < 0 || v as usize >= nv {
                return Err(PlyError::BadIndex { face: i, index: i64::from(v), vertices: nv });
            }
            t[k] = v as u32;
        }
        mesh.triangles.push(t);
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Mesh {
        Mesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.5], [0.0, 1.0, -0.25]],
            normals: vec![],
            colors: vec![[255, 0, 0], [0, 255, 0], [0, 0, 255]],
            triangles: vec![[0, 1, 2]],
        }
    }

    #[test]
    fn round_trip_through_a_file() {
        let path = std::env::temp_dir().join(format!("xsurf-ply-{}.ply", std::process::id()));
        write_file(&path, &sample()).unwrap();
        let m = read(&mut std::io::BufReader::new(std::fs::File::open(&path).unwrap())).unwrap();
        assert_eq!(m.positions, sample().positions);
        assert_eq!(m.colors, sample().colors);
        assert_eq!(m.triangles, sample().triangles);
        std::fs::remove_file(&path).unwrap();
    }

    #[test]
    fn truncated_and_bad_files_are_errors() {
        let mut bytes = Vec::new();
        write(&mut bytes, &sample()).unwrap();
        let cut = &bytes[..bytes.len() - 5];
        assert!(matches!(read(&mut &cut[..]), Err(PlyError::Truncated { element: "face", index: 0, .. })));
        assert!(matches!(read(&mut &b"plx\nend_header\n"[..]), Err(PlyError::Header(_))));
        let n = bytes.len();
        bytes[n - 4..].copy_from_slice(&7i32.to_le_bytes());
        assert!(matches!(read(&mut &bytes[..]), Err(PlyError::BadIndex { index: 7, .. })));
    }
}
