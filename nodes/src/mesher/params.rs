//! The parameters of `mesher`, declared once (see `xsurf_runtime::parameters!`).

use std::path::PathBuf;
use xsurf_core::edge::Orientation;
use xsurf_core::mesh::MeshConfig;

/// The mesh's defaults (core's), which the declarations show.
const D: MeshConfig = MeshConfig::DEFAULT;

xsurf_runtime::parameters! {
    /// The parameters of `mesher`.
    pub struct MesherParams {
        /// longest triangle edge
        max_edge_m: f32 = D.max_edge_m, unit "m";
        /// extra edge length per metre of camera range (PCL's depth term)
        max_edge_per_m: f32 = D.max_edge_per_m, unit "m/m";
        /// smallest triangle angle (the study used 12)
        min_angle_deg: f32 = D.min_angle_deg, unit "deg";
        /// fill isolated single missing points by interpolation
        fill_single_holes: bool = D.fill_single_holes;
        /// a point that its grid neighbours (along its frame or across frames) miss by more than
        /// this is rejected before meshing and counted: a wrong peak, a highlight, an occlusion
        /// edge's mixed pixel (0: keep every point)
        outlier_tolerance_m: f32 = D.outlier_tolerance_m, unit "m";
        /// a point at a surface's edge across frames (the first or last frame on it) is rejected
        /// before meshing and counted when its one neighbour across frames has at least this many
        /// times its laser strength: the sheet only partly reached it, and its centre is the part's,
        /// off the surface (1 or less: keep them)
        partial_sheet_ratio: f32 = D.partial_sheet_ratio, range 0.0..=1000.0;
        /// Laplacian smoothing passes (boundary kept)
        smooth_iterations: u32 = D.smooth_iterations;
        /// Laplacian step, (0, 1]
        smooth_lambda: f32 = D.smooth_lambda;
        /// how often the growing cloud is published during a scan (0: only at END)
        cloud_rate_hz: f64 = 2.0, unit "Hz", range 0.0..=1000.0;
        /// how often the growing surface is published during a scan: the triangles of the frames
        /// since the last part only (unsmoothed, uncleaned), each part a marker of its own
        /// (namespace <camera>_growing, ids 0, 1, ...) that a viewer keeps, so the surface grows
        /// behind the C-arm; at END a DELETEALL clears them before the scan's mesh (0: the mesh
        /// only at END)
        mesh_rate_hz: f64 = 2.0, unit "Hz", range 0.0..=1000.0;
        /// the growing surface takes every n-th sample of each frame (a preview: 4 quarters its
        /// triangles and the bytes on the wire, which a composed graph's one DDS participant
        /// sends beside the camera chains'; the scan's mesh at END has every sample)
        mesh_preview_stride: u32 = 4, range 1..=64;
        /// after END the mesh marker is published again this often until the next scan, so
        /// viewers that join late or lose it (best effort) get it (0: once)
        mesh_republish_s: f64 = 2.0, unit "s", range 0.0..=3600.0;
        /// the scanner's lasers by name (empty: one laser): each profile holds a block of samples
        /// per laser, kept as one grid per laser and meshed apart; the cloud stacks them, with
        /// a field `laser` (the index into this list)
        lasers: Vec<String> = Vec::new();
        /// if set, each scan's mesh is written to <output_dir>/scan_<id>/<camera>.ply
        output_dir: Option<PathBuf> = None;
        /// camera name for files and markers (default: the node's namespace)
        camera: String = String::new();
        /// frame of the clouds and meshes
        frame_id: String = "table".into();
        /// a stamp gap above this many nominal frame periods counts as dropped frames
        gap_factor: f64 = 1.5;
        /// after END or ABORT, profiles stamped before it (exposed in the scan, still on their
        /// way) are taken for this long before the scan is closed (0: close at END)
        end_grace_s: f64 = 0.3, unit "s", range 0.0..=10.0;
        /// as the edge detector's: vertical (a sample per image row) or horizontal (per column);
        /// with camera_info it gives the samples per frame, and a profile of another size is refused
        line_orientation: Orientation = Orientation::Vertical, via Choice;
    }
}

