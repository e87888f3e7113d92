//! The parameters of `xray_aligner`, declared once (see `xsurf_runtime::parameters!`).

use std::path::PathBuf;

xsurf_runtime::choice! {
    /// Where the radiograph comes from.
    pub enum ImageSource {
        /// `dicom_file`, published on `/xray/image`.
        Dicom = "dicom",
        /// `/xray/image`.
        Topic = "topic",
    }
}

xsurf_runtime::choice! {
    /// What bounds the exposure in time.
    pub enum ExposureTiming {
        /// The scan's START..END.
        Events = "events",
        /// The DICOM's Acquisition DateTime and Exposure Time.
        Dicom = "dicom",
    }
}

xsurf_runtime::parameters! {
    /// The parameters of `xray_aligner`.
    pub struct XrayAlignerParams {
        /// dicom: load dicom_file and publish it on /xray/image; topic: take the radiograph from
        /// /xray/image
        image_source: ImageSource = ImageSource::Dicom, via Choice;
        /// DICOM radiograph to load; setting it while running loads it (the request)
        dicom_file: String = String::new();
        /// with image_source topic: values rise with dose (MONOCHROME1)
        topic_monochrome1: bool = true;
        /// fan-beam plane in carm [nx, ny, nz, d]
        laser_plane: Vec<f64> = vec![0.0, 1.0, 0.0, 0.0], unit "m";
        /// X-ray focal spot in carm [x, y, z]
        laser_source: Vec<f64> = vec![0.0, 0.0, 1.2], unit "m";
        /// focal spot to detector line; 0: the DICOM's Distance Source to Detector
        source_detector_m: f64 = 0.0, unit "m", range 0.0..=1e6;
        /// detector element pitch; 0: the DICOM's Imager Pixel Spacing (column spacing)
        detector_pitch_m: f64 = 0.0, unit "m", range 0.0..=1e6;
        /// detector column under the focal spot (pixel edges at integers); -1: the middle
        center_column: f64 = -1.0, unit "px";
        /// detector columns run towards -X of carm
        flip_columns: bool = false;
        /// height above the tabletop of the plane the radiograph lies on
        plane_height_m: f64 = 0.0, unit "m";
        /// edge columns with less than this fraction of the typical dose are cropped; 0: no crop
        crop_threshold: f64 = 0.1;
        /// display window centre (rescaled units), used when window_width >= 1
        window_center: f64 = 0.0;
        /// display window width; 0: the file's window or VOI LUT, else automatic
        window_width: f64 = 0.0;
        /// events: the scan's START..END; dicom: Acquisition DateTime + Exposure Time
        exposure_timing: ExposureTiming = ExposureTiming::Events, via Choice;
        /// overlay grid cells across (vertex colours stand in for the texture)
        grid_columns: u32 = 96, range 1..=1024;
        /// overlay grid cells along the scan (follows the travel)
        grid_rows: u32 = 128, range 1..=1024;
        /// after END, how long to wait for a pose past the exposure end
        wait_for_pose_s: f64 = 2.0, unit "s", range 0.0..=3600.0;
        /// if set, <output_dir>/scan_<id>/xray.png and xray.json are written
        output_dir: Option<PathBuf> = None;
        /// frame of the overlay
        frame_id: String = "table".into();
        /// tf frame of the tabletop
        table_frame: String = "table".into();
        /// tf frame of the C-arm
        carm_frame: String = "carm".into();
    }
}

