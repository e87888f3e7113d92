//! The parameters of `merger`, declared once (see `xsurf_runtime::parameters!`).

use std::path::PathBuf;
use xsurf_core::fuse::FuseConfig;
use xsurf_core::mesh::MeshConfig;
use xsurf_core::register::RefineConfig;

xsurf_runtime::parameters! {
    /// The parameters of `merger`.
    pub struct MergerParams {
        /// camera namespaces whose /<cam>/cloud are merged
        cameras: Vec<String> = vec!["cam1".into(), "cam2".into()];
        /// the longest wait after END for the cameras' final clouds: the merge starts as soon as every
        /// camera's mesher has reported its final cloud (`final_cloud` in its report) and that cloud is
        /// in, or at this bound without the missing ones
        merge_delay_s: f64 = 1.0, unit "s", range 0.0..=600.0;
        /// longest triangle edge when meshing each camera's grid
        max_edge_m: f32 = MeshConfig::DEFAULT.max_edge_m, unit "m";
        /// smallest triangle angle
        min_angle_deg: f32 = MeshConfig::DEFAULT.min_angle_deg, unit "deg";
        /// where cameras overlap, samples of different cameras closer than this are one
        /// observation: the region's better-lit camera keeps it, averaged with the other's (0:
        /// keep both layers)
        fuse_distance_m: f32 = FuseConfig::DEFAULT.min_distance_m, unit "m", range 0.0..=0.05;
        /// stitch the seams between the cameras' surfaces in the merged mesh (triangles within
        /// max_edge_m and min_angle_deg)
        zipper: bool = true;
        /// after zippering, each hole in the merged surface bounded by at most this many edges
        /// is closed with triangles whose new edges are within max_edge_m; wider holes and the
        /// outer rim stay open (0: none)
        max_hole_edges: usize = 64, range 0..=100_000;
        /// refine each further camera's placement against the first camera's surface (false:
        /// calibration only)
        refine: bool = true;
        /// the scanner's lasers by name (empty: one laser): each camera's cloud holds a block
        /// of samples per laser; every camera's and laser's grid is fused into one layer, and
        /// the merged cloud has a field `laser` (the index into this list)
        lasers: Vec<String> = Vec::new();
        /// the laser plane in carm, [nx, ny, nz, d], as the triangulators have it (the
        /// refinement re-triangulates)
        laser_plane: Vec<f64> = vec![0.0, 1.0, 0.0, 0.0], unit "m";
        /// a refinement that moves a camera further than this is refused
        refine_max_translation_m: f64 = RefineConfig::DEFAULT.max_translation_m, unit "m";
        /// a refinement that turns a camera further than this is refused
        refine_max_rotation_deg: f64 = RefineConfig::DEFAULT.max_rotation_deg, unit "deg";
        /// a refinement whose RMS point-to-plane residual stays above this is refused
        refine_max_rms_m: f64 = RefineConfig::DEFAULT.max_rms_m, unit "m";
        /// if set, each refined placement is written into this rig file (atomically), for the
        /// next scans
        save_rig_file: Option<PathBuf> = None;
        /// surface transparency in the VRML and glTF scenes, 0..1
        transparency: f32 = 0.3, range 0.0..=1.0;
        /// if set, each scan's merged.ply, scene.wrl and scene.glb go to <output_dir>/scan_<id>/
        output_dir: Option<PathBuf> = None;
        /// frame of the merged cloud and mesh
        frame_id: String = "table".into();
        /// the fixed frame of `table -> carm` on /tf (the C-arm's motion over a scan)
        table_frame: String = "table".into();
        /// the C-arm frame: of /tf, of the cameras' placements on /tf_static and of those the
        /// refinement publishes on /surface/placements
        carm_frame: String = "carm".into();
        /// the merged cloud and mesh are published again this often until the next scan, for
        /// viewers that join late or lose them (best effort) (0: once)
        republish_s: f64 = 2.0, unit "s", range 0.0..=3600.0;
        /// the radiograph's DICOM file: each scan's surface.dcm joins its patient and study, and
        /// the radiograph is written beside it in the scan's frame (xray.dcm); the same file as
        /// xray_aligner's dicom_file (set both, under /** in a params file) ("": none)
        dicom_file: String = String::new();
        /// without a radiograph: the Patient ID in surface.dcm; with one that has none, this one
        patient_id: String = String::new();
        /// without a radiograph: the Patient's Name in surface.dcm (DICOM PN, Family^Given)
        patient_name: String = String::new();
        /// without a radiograph: the Accession Number of the order
        accession_number: String = String::new();
        /// without a radiograph: the Study Instance UID the scans join ("": a new study per scan)
        study_instance_uid: String = String::new();
        /// also write the merged points with their colours as a Surface Scan Point Cloud (points.dcm)
        point_cloud_dcm: bool = false;
        /// the PACS each scan's DICOM files are sent to, AET@host:port; a scan waits in
        /// pacs_queue_dir until the PACS has stored it ("": none)
        pacs: String = String::new();
        /// our AE title towards the PACS (the calling AE title)
        ae_title: String = "XSURF".into();
        /// where scans wait for the PACS (default: <output_dir>/pacs_queue)
        pacs_queue_dir: Option<PathBuf> = None;
        /// the scanner's Device Serial Number in the DICOM files
        device_serial_number: String = "0".into();
        /// the Institution Name in the DICOM files ("": none)
        institution_name: String = String::new();
    }
}

