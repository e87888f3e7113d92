//! Conversions between messages and the algorithms' types.

use xsurf_core::camera::{CameraError, CameraModel};
use xsurf_core::edge::{LaserLine as CoreLine, Orientation};
use xsurf_core::geom::{Iso3, Quat, Vec3};
use xsurf_core::image::{Encoding, Image as CoreImage, ImageError, ImageView};
use xsurf_core::mesh::{Grid, Mesh};
use xsurf_core::triangulate::Profile;
use xsurf_msgs::builtin_interfaces::Time;
use xsurf_msgs::geometry_msgs::{Point, Quaternion, Transform, TransformStamped, Vector3};
use xsurf_msgs::pointcloud;
use xsurf_msgs::sensor_msgs::{CameraInfo, Image, PointCloud2};
use xsurf_msgs::std_msgs::{ColorRGBA, Header};
use xsurf_msgs::visualization_msgs::Marker;
use xsurf_msgs::xsurf_msgs::LaserLine;

/// A checked view of an `Image` message's pixels for the algorithms.
pub fn image_view(img: &Image) -> Result<ImageView<'_>, ImageError> {
    let enc = Encoding::from_ros(&img.encoding)?;
    ImageView::new(img.width, img.height, img.step, enc, img.is_bigendian != 0, &img.data)
}

/// An `Image` message holding an owned image.
pub fn image_msg(header: Header, img: CoreImage) -> Image {
    Image {
        header,
        height: img.height,
        width: img.width,
        encoding: img.encoding.ros_name().to_string(),
        is_bigendian: 0,
        step: img.step(),
        data: img.data,
    }
}

/// A header.
pub fn header(stamp_ns: i64, frame_id: &str) -> Header {
    Header { stamp: Time::from_nanos(stamp_ns), frame_id: frame_id.to_string() }
}

/// Intrinsics from a `CameraInfo` (binning and ROI are not handled and are refused).
pub fn camera_model(info: &CameraInfo) -> Result<CameraModel, CameraError> {
    if info.binning_x > 1 || info.binning_y > 1 || info.roi.width != 0 {
        return Err(CameraError::InvalidIntrinsics("binning and ROI in camera_info are not supported".into()));
    }
    CameraModel::from_ros(info.width, info.height, &info.k, &info.distortion_model, &info.d)
}

/// A `CameraInfo` for intrinsics (no rectification: R = I, P = [K | 0]).
pub fn camera_info(model: &CameraModel, header: Header) -> CameraInfo {
    let (dm, d) = model.distortion.to_ros();
    let k = model.k();
    CameraInfo {
        header,
        height: model.height,
        width: model.width,
        distortion_model: dm.to_string(),
        d,
        k,
        r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: [k[0], 0.0, k[2], 0.0, 0.0, k[4], k[5], 0.0, 0.0, 0.0, 1.0, 0.0],
        ..Default::default()
    }
}

/// A transform message's pose.
pub fn iso(t: &Transform) -> Iso3 {
    let r = t.rotation;
    Iso3::from_parts(
        Vec3::new(t.translation.x, t.translation.y, t.translation.z),
        Quat { x: r.x, y: r.y, z: r.z, w: r.w },
    )
}

/// A received transform's pose, checked as tf2 checks what it is given (`TF_NAN_INPUT`,
/// `TF_DENORMALIZED_QUATERNION`, no frame id, a self transform): a finite translation and a
/// quaternion whose squared norm is within 0.01 of 1 (normalized here), between two named,
/// different frames. The error names the transform and what is wrong with it.
pub fn rigid(t: &TransformStamped) -> Result<Iso3, String> {
    let (parent, child) = (t.header.frame_id.trim_start_matches('/'), t.child_frame_id.trim_start_matches('/'));
    let name = format!("transform {parent:?} -> {child:?}");
    if parent.is_empty() || child.is_empty() {
        return Err(format!("{name}: a frame id is empty"));
    }
    if parent == child {
        return Err(format!("{name}: a frame cannot be its own parent"));
    }
    let (v, q) = (t.transform.translation, t.transform.rotation);
    if ![v.x, v.y, v.z].iter().all(|x| x.is_finite()) {
        return Err(format!("{name}: translation ({}, {}, {}) is not finite", v.x, v.y, v.z));
    }
    let n2 = q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w;
    if !n2.is_finite() || (n2 - 1.0).abs() > 0.01 {
        return Err(format!(
            "{name}: rotation ({}, {}, {}, {}) is not a unit quaternion (norm {:.4})",
            q.x,
            q.y,
            q.z,
            q.w,
            n2.sqrt()
        ));
    }
    let n = n2.sqrt();
    Ok(Iso3::from_parts(Vec3::new(v.x, v.y, v.z), Quat { x: q.x / n, y: q.y / n, z: q.z / n, w: q.w / n }))
}

/// A pose as a stamped transform `parent -> child`.
pub fn transform_stamped(stamp_ns: i64, parent: &str, child: &str, t: &Iso3) -> TransformStamped {
    let q = t.quaternion();
    TransformStamped {
        header: header(stamp_ns, parent),
        child_frame_id: child.to_string(),
        transform: Transform {
            translation: Vector3 { x: t.translation.x, y: t.translation.y, z: t.translation.z },
            rotation: Quaternion { x: q.x, y: q.y, z: q.z, w: q.w },
        },
    }
}

/// The message form of several lasers' lines in one image: one block of samples per laser, in
/// the order of `lasers` (empty: one line, the single laser); with twice as many lines as
/// lasers, each laser's second surfaces' line after every laser's first (`lines` layer-major, as
/// `LaserDetectors::detect` writes them) and `layers` 2.
pub fn lines_msg(lines: &[CoreLine], lasers: &[String], header: Header) -> LaserLine {
    let first = lines.first();
    let layers = lines.len() / lasers.len().max(1);
    let cat = |f: fn(&CoreLine) -> &Vec<f32>| lines.iter().flat_map(|l| f(l).iter().copied()).collect::<Vec<f32>>();
    LaserLine {
        header,
        image_width: first.map_or(0, |l| l.image_width),
        image_height: first.map_or(0, |l| l.image_height),
        orientation: match first.map_or(Orientation::Vertical, |l| l.orientation) {
            Orientation::Vertical => LaserLine::ORIENTATION_VERTICAL,
            Orientation::Horizontal => LaserLine::ORIENTATION_HORIZONTAL,
        },
        u: cat(|l| &l.u),
        v: cat(|l| &l.v),
        strength: cat(|l| &l.strength),
        width: cat(|l| &l.width),
        rgb: lines.iter().flat_map(|l| l.rgb.iter().copied()).collect(),
        lasers: lasers.to_vec(),
        layers: if layers > 1 { u8::try_from(layers).unwrap_or(u8::MAX) } else { 0 },
    }
}

/// The most lines per laser a `LaserLine` carries (field `layers`): the first, and a second
/// surface's.
pub const MAX_LAYERS: u8 = 2;

/// Why a `LaserLine` message cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LineShapeError {
    /// The per-sample arrays have different lengths.
    #[error(
        "LaserLine arrays disagree: u {u}, v {v}, strength {strength}, width {width}, rgb {rgb} (expected rgb 0 or 3 x u)"
    )]
    Arrays {
        /// Length of `u`.
        u: usize,
        /// Length of `v`.
        v: usize,
        /// Length of `strength`.
        strength: usize,
        /// Length of `width`.
        width: usize,
        /// Length of `rgb`.
        rgb: usize,
    },
    /// The lasers named are not the ones this node was given.
    #[error("LaserLine is of lasers {got:?}; this node's lasers (parameter lasers) are {expected:?}")]
    Lasers {
        /// The message's `lasers`.
        got: Vec<String>,
        /// The node's.
        expected: Vec<String>,
    },
    /// More lines per laser than a detector writes.
    #[error("LaserLine has layers {0}: 0 or 1 (one line per laser) or 2 (and a second surface's)")]
    Layers(u8),
    /// The orientation is neither vertical (0) nor horizontal (1).
    #[error("LaserLine orientation {0} is neither 0 (vertical) nor 1 (horizontal)")]
    Orientation(u8),
    /// The image size is outside the limits every tool applies.
    #[error("LaserLine image size {0}x{1} is outside {2} pixels a side")]
    ImageSize(u32, u32, String),
    /// The sample count is not one per row (vertical) or column (horizontal) of its image, for
    /// each laser and layer.
    #[error("LaserLine has {samples} samples; a {orientation} line of a {width}x{height} image has {expected} (times its lasers and layers)")]
    Samples {
        /// Samples in the message.
        samples: usize,
        /// One per row or column.
        expected: u32,
        /// "vertical" or "horizontal".
        orientation: &'static str,
        /// Image width.
        width: u32,
        /// Image height.
        height: u32,
    },
}

/// The algorithm form of a line message, one line per block of samples (`lasers`, or one block
/// without; with `layers` 2 every laser's first line, then every laser's second), checking that
/// each describes a line of its image: arrays of one length, a known orientation, an image
/// within the limits, at most 2 layers, and one sample per row (vertical) or column
/// (horizontal), laser and layer.
pub fn core_lines(m: &LaserLine) -> Result<Vec<CoreLine>, LineShapeError> {
    let n = m.u.len();
    if m.v.len() != n || m.strength.len() != n || m.width.len() != n || !(m.rgb.is_empty() || m.rgb.len() == 3 * n) {
        return Err(LineShapeError::Arrays {
            u: n,
            v: m.v.len(),
            strength: m.strength.len(),
            width: m.width.len(),
            rgb: m.rgb.len(),
        });
    }
    let (orientation, expected, name) = match m.orientation {
        LaserLine::ORIENTATION_VERTICAL => (Orientation::Vertical, m.image_height, "vertical"),
        LaserLine::ORIENTATION_HORIZONTAL => (Orientation::Horizontal, m.image_width, "horizontal"),
        other => return Err(LineShapeError::Orientation(other)),
    };
    if !xsurf_core::limits::image_side_ok(m.image_width) || !xsurf_core::limits::image_side_ok(m.image_height) {
        return Err(LineShapeError::ImageSize(m.image_width, m.image_height, xsurf_core::limits::image_side_text()));
    }
    if m.layers > MAX_LAYERS {
        return Err(LineShapeError::Layers(m.layers));
    }
    let blocks = m.lasers.len().max(1) * m.layer_count();
    if m.lasers.len() > xsurf_core::rig::MAX_LASERS || n != expected as usize * blocks {
        return Err(LineShapeError::Samples {
            samples: n,
            expected: expected * blocks as u32,
            orientation: name,
            width: m.image_width,
            height: m.image_height,
        });
    }
    let k = expected as usize;
    let rgb = !m.rgb.is_empty();
    Ok((0..blocks)
        .map(|b| CoreLine {
            orientation,
            image_width: m.image_width,
            image_height: m.image_height,
            u: m.u[b * k..(b + 1) * k].to_vec(),
            v: m.v[b * k..(b + 1) * k].to_vec(),
            strength: m.strength[b * k..(b + 1) * k].to_vec(),
            width: m.width[b * k..(b + 1) * k].to_vec(),
            rgb: if rgb { m.rgb[3 * b * k..3 * (b + 1) * k].to_vec() } else { Vec::new() },
        })
        .collect())
}

/// A one-frame profile as an organized cloud (height = samples, width 1).
pub fn profile_cloud(p: &Profile, header: Header) -> PointCloud2 {
    pointcloud::build(header, p.points.len() as u32, 1, |r, _| {
        (p.points[r], p.intensity[r], p.rgb.as_ref().map_or(0, |c| c[r]))
    })
}

/// How the samples of a profile (or a grid's frame) are laid out in blocks: `lasers` lasers
/// (0: `lasers` unset, one laser and no field `laser`) and `layers` lines per laser (2: every
/// laser's first line, then every laser's second, and the field `layer`; 1: no field).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Blocks {
    /// The lasers named (0: one laser, unnamed).
    pub lasers: usize,
    /// Lines per laser (1 or 2).
    pub layers: usize,
}

impl Blocks {
    /// One laser, one line: the single block, without the fields `laser` and `layer`.
    pub const ONE: Blocks = Blocks { lasers: 0, layers: 1 };

    /// The number of blocks of samples.
    pub fn count(&self) -> usize {
        self.lasers.max(1) * self.layers.max(1)
    }

    /// Sample `r` of a profile of `samples` samples: its laser's index and its layer.
    fn of(&self, r: usize, samples: usize) -> (f32, f32) {
        let block = r / (samples / self.count()).max(1);
        let lasers = self.lasers.max(1);
        ((block % lasers) as f32, (block / lasers) as f32)
    }

    /// The fields `laser` and `layer`, as the blocks call for them.
    fn fields(&self) -> (bool, bool) {
        (self.lasers > 0, self.layers > 1)
    }
}

/// A one-frame profile in `blocks` as an organized cloud (height = samples, width 1), with the
/// field `laser` (the sample's block's laser) with named lasers and `layer` (0 or 1) with
/// second lines; [`profile_cloud`] without either.
pub fn profile_cloud_blocks(p: &Profile, header: Header, blocks: Blocks) -> PointCloud2 {
    if blocks.fields() == (false, false) {
        return profile_cloud(p, header);
    }
    let n = p.points.len();
    pointcloud::build_tagged(header, n as u32, 1, blocks.fields(), |r, _| {
        let (laser, layer) = blocks.of(r, n);
        (p.points[r], p.intensity[r], p.rgb.as_ref().map_or(0, |c| c[r]), laser, layer)
    })
}

/// An organized cloud as a grid: one profile per column (range is not carried: NaN). Grey
/// cameras send rgb 0; then no colour is kept and meshes take their grey from the strength.
pub fn cloud_grid(c: &PointCloud2) -> Result<Grid, pointcloud::CloudError> {
    let pts = pointcloud::read(c)?;
    let (h, w) = (c.height as usize, c.width as usize);
    let has_rgb = pts.iter().any(|p| p.rgb.is_some_and(|v| v != 0));
    let mut g = Grid::new(h);
    for col in 0..w {
        let at = |r: usize| &pts[r * w + col];
        let p = Profile {
            points: (0..h).map(|r| at(r).xyz).collect(),
            intensity: (0..h).map(|r| at(r).intensity.unwrap_or(0.0)).collect(),
            rgb: has_rgb.then(|| (0..h).map(|r| at(r).rgb.unwrap_or(0)).collect()),
            range: vec![f32::NAN; h],
            outside_volume: 0,
        };
        // Every column has h samples, so the push cannot be refused.
        let _ = g.push(col as i64, &p);
    }
    Ok(g)
}

/// Why a profile cloud cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ProfileError {
    /// The cloud itself is malformed.
    #[error(transparent)]
    Cloud(#[from] pointcloud::CloudError),
    /// A profile is one frame: one column.
    #[error("a profile has width 1 (one frame), got width {0}")]
    Width(u32),
}

/// A profile from a one-frame cloud (the mesher's input).
pub fn cloud_profile(c: &PointCloud2) -> Result<Profile, ProfileError> {
    if c.width != 1 {
        return Err(ProfileError::Width(c.width));
    }
    let g = cloud_grid(c)?;
    Ok(Profile {
        points: g.points().to_vec(),
        intensity: g.intensity().to_vec(),
        rgb: g.has_rgb().then(|| g.rgb().to_vec()),
        range: g.range().to_vec(),
        outside_volume: 0,
    })
}

/// `sec.nanosec` of a stamp, for messages.
pub fn fmt_stamp(ns: i64) -> String {
    format!("{}.{:09}", ns.div_euclid(1_000_000_000), ns.rem_euclid(1_000_000_000))
}

/// The organized grid so far: height = samples per frame, width = frames.
pub fn grid_cloud(g: &Grid, header: Header) -> PointCloud2 {
    let ns = g.samples();
    pointcloud::build(header, ns as u32, g.frames() as u32, |r, c| {
        let i = c * ns + r;
        (g.points()[i], g.intensity()[i], g.rgb()[i])
    })
}

/// Lines per laser in a profile or grid cloud: 2 where it has the field `layer` (second
/// surfaces' lines), else 1.
pub fn cloud_layers(c: &PointCloud2) -> usize {
    if pointcloud::has_layers(c) {
        2
    } else {
        1
    }
}

/// The organized grid of a scanner whose profiles hold `blocks` (a block of samples per laser
/// and line), with the fields `laser` and `layer` as [`profile_cloud_blocks`] has them.
pub fn grid_cloud_blocks(g: &Grid, header: Header, blocks: Blocks) -> PointCloud2 {
    if blocks.fields() == (false, false) {
        return grid_cloud(g, header);
    }
    let ns = g.samples();
    pointcloud::build_tagged(header, ns as u32, g.frames() as u32, blocks.fields(), |r, c| {
        let i = c * ns + r;
        let (laser, layer) = blocks.of(r, ns);
        (g.points()[i], g.intensity()[i], g.rgb()[i], laser, layer)
    })
}

/// A mesh as an rviz2 `TRIANGLE_LIST` marker with per-vertex colours.
pub fn mesh_marker(mesh: &Mesh, header: Header, ns: &str, id: i32, alpha: f32) -> Marker {
    let mut points = Vec::with_capacity(mesh.triangles.len() * 3);
    let mut colors = Vec::with_capacity(mesh.triangles.len() * 3);
    for t in &mesh.triangles {
        for &i in t {
            let p = mesh.positions[i as usize];
            points.push(Point { x: p[0].into(), y: p[1].into(), z: p[2].into() });
            let c = mesh.colors.get(i as usize).copied().unwrap_or([200, 200, 200]);
            colors.push(ColorRGBA {
                r: f32::from(c[0]) / 255.0,
                g: f32::from(c[1]) / 255.0,
                b: f32::from(c[2]) / 255.0,
                a: alpha,
            });
        }
    }
    Marker {
        header,
        ns: ns.to_string(),
        id,
        type_: Marker::TRIANGLE_LIST,
        action: Marker::ADD,
        pose: Default::default(),
        scale: Vector3 { x: 1.0, y: 1.0, z: 1.0 },
        color: ColorRGBA { r: 0.8, g: 0.8, b: 0.8, a: alpha },
        points,
        colors,
        ..Default::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_info_round_trip() {
        let rig = xsurf_core::rig::Rig::study(640, 480);
        let m = rig.cameras[0].model().unwrap();
        let info = camera_info(&m, Header::default());
        assert_eq!(camera_model(&info).unwrap(), m);
        let mut bad = info.clone();
        bad.distortion_model = "fisheye".into();
        assert!(camera_model(&bad).is_err());
    }

    #[test]
    fn transform_round_trip() {
        let t = Iso3::look_at(Vec3::new(0.1, 0.2, 0.8), Vec3::ZERO, Vec3::X).unwrap();
        let back = iso(&transform_stamped(0, "carm", "cam1_optical_frame", &t).transform);
        let p = Vec3::new(0.3, -0.2, 0.5);
        assert!((back.transform_point(p) - t.transform_point(p)).norm() < 1e-12);
    }

    #[test]
    fn organized_clouds_read_back_as_grids_and_profiles() {
        let mut g = Grid::new(3);
        for f in 0..2 {
            let p = Profile {
                points: (0..3).map(|s| [s as f32, f as f32, 0.0]).collect(),
                intensity: vec![50.0; 3],
                rgb: None,
                range: vec![1.0; 3],
                outside_volume: 0,
            };
            g.push(f, &p).unwrap();
        }
        let back = cloud_grid(&grid_cloud(&g, Header::default())).unwrap();
        assert_eq!(back.points(), g.points());
        assert!(!back.has_rgb(), "grey stays grey");
        let wide = grid_cloud(&g, Header::default());
        assert!(matches!(cloud_profile(&wide), Err(ProfileError::Width(2))));
        let mut colour = Grid::new(3);
        let red = Profile {
            points: vec![[1.0; 3]; 3],
            intensity: vec![1.0; 3],
            rgb: Some(vec![0x00ff0000; 3]),
            range: vec![0.0; 3],
            outside_volume: 0,
        };
        colour.push(0, &red).unwrap();
        assert_eq!(cloud_profile(&grid_cloud(&colour, Header::default())).unwrap().rgb, Some(vec![0x00ff0000; 3]));
    }

    #[test]
    fn inconsistent_line_is_refused() {
        let m = LaserLine { u: vec![1.0], v: vec![], ..Default::default() };
        assert!(core_lines(&m).is_err());
    }

    /// A line with second surfaces' lines: blocks per laser and line, layer-major, and the
    /// message says so; more than two lines per laser, or samples for fewer, are refused.
    #[test]
    fn second_lines_make_blocks_of_their_own() {
        let line = |u: f32| CoreLine {
            orientation: Orientation::Vertical,
            image_width: 64,
            image_height: 32,
            u: vec![u; 32],
            v: (0..32).map(|v| v as f32).collect(),
            strength: vec![9.0; 32],
            width: vec![2.0; 32],
            rgb: Vec::new(),
        };
        let lasers = ["collimator".to_string(), "left".to_string()];
        let lines = [line(1.0), line(2.0), line(3.0), line(4.0)];
        let m = lines_msg(&lines, &lasers, Header::default());
        assert_eq!((m.layers, m.u.len()), (2, 128));
        let back = core_lines(&m).unwrap();
        assert_eq!(back.iter().map(|l| l.u[0]).collect::<Vec<_>>(), vec![1.0, 2.0, 3.0, 4.0]);
        assert_eq!(lines_msg(&lines[..2], &lasers, Header::default()).layers, 0);
        assert_eq!(core_lines(&LaserLine { layers: 3, ..m.clone() }), Err(LineShapeError::Layers(3)));
        let short = LaserLine { layers: 2, ..lines_msg(&lines[..2], &lasers, Header::default()) };
        assert!(matches!(core_lines(&short), Err(LineShapeError::Samples { samples: 64, expected: 128, .. })));
        // The blocks' laser and line, as the profile's fields have them.
        let b = Blocks { lasers: 2, layers: 2 };
        assert_eq!((b.count(), b.of(3, 12), b.of(7, 12), b.of(11, 12)), (4, (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)));
        assert_eq!((Blocks::ONE.count(), Blocks { lasers: 0, layers: 2 }.of(5, 6)), (1, (0.0, 1.0)));
    }
}
