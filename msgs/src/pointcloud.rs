//! `PointCloud2` with the fields xsurf uses: `x y z intensity rgb` (all FLOAT32; `rgb` holds
//! 0x00RRGGBB in its bits, the PCL convention rviz2 reads), organized, NaN where no point.

use crate::sensor_msgs::{PointCloud2, PointField};
use crate::std_msgs::Header;

/// Bytes per point of the clouds we write.
pub const POINT_STEP: u32 = 20;

/// One point as read from a cloud.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CloudPoint {
    /// Position.
    pub xyz: [f32; 3],
    /// Laser strength, if the cloud has it.
    pub intensity: Option<f32>,
    /// Colour 0x00RRGGBB, if the cloud has it.
    pub rgb: Option<u32>,
}

/// Why a cloud cannot be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CloudError {
    /// `width * height * point_step` disagrees with the data.
    #[error("PointCloud2 size mismatch: width {width} x height {height} x point_step {point_step} != {len} data bytes (row_step {row_step})")]
    Size {
        /// Width.
        width: u32,
        /// Height.
        height: u32,
        /// Point step.
        point_step: u32,
        /// Row step.
        row_step: u32,
        /// Data length.
        len: usize,
    },
    /// A required field is missing or not FLOAT32.
    #[error("PointCloud2 field {0:?} is missing or not FLOAT32")]
    Field(&'static str),
    /// A field lies outside the point.
    #[error("PointCloud2 field {name:?} at offset {offset} does not fit in point_step {point_step}")]
    FieldOutside {
        /// Field.
        name: String,
        /// Offset.
        offset: u32,
        /// Point step.
        point_step: u32,
    },
    /// Big-endian clouds are not handled.
    #[error("big-endian PointCloud2 is not supported")]
    BigEndian,
}

/// Builds an organized `x y z intensity rgb` cloud of `height` rows and `width` columns.
/// `point(r, c)` gives the point at row `r`, column `c`.
pub fn build(
    header: Header,
    height: u32,
    width: u32,
    mut point: impl FnMut(usize, usize) -> ([f32; 3], f32, u32),
) -> PointCloud2 {
    let n = height as usize * width as usize;
    // Sized once and written in place: no capacity check per field.
    let mut data = vec![0u8; n * POINT_STEP as usize];
    let mut dense = true;
    let mut slots = data.chunks_exact_mut(POINT_STEP as usize);
    for r in 0..height as usize {
        for (c, slot) in (0..width as usize).zip(slots.by_ref()) {
            let (p, i, rgb) = point(r, c);
            dense &= p.iter().all(|v| v.is_finite());
            let words = [p[0].to_bits(), p[1].to_bits(), p[2].to_bits(), i.to_bits(), rgb];
            for (dst, w) in slot.chunks_exact_mut(4).zip(words) {
                dst.copy_from_slice(&w.to_le_bytes());
            }
        }
    }
    cloud(header, height, width, data, dense)
}

/// Builds the same cloud as [`build`] from column-major arrays (point `(r, c)` at index
/// `c * height + r`, as a scan's grid stores its frames), transposing in blocks of rows so that
/// both the reads and the writes stay in cache. `None` if an array is shorter than
/// `height * width`.
pub fn build_from_columns(
    header: Header,
    height: u32,
    width: u32,
    xyz: &[[f32; 3]],
    intensity: &[f32],
    rgb: &[u32],
) -> Option<PointCloud2> {
    const BLOCK: usize = 16;
    let (h, w) = (height as usize, width as usize);
    let n = h * w;
    if xyz.len() < n || intensity.len() < n || rgb.len() < n {
        return None;
    }
    let step = POINT_STEP as usize;
    let mut data = vec![0u8; n * step];
    let mut dense = true;
    for r0 in (0..h).step_by(BLOCK) {
        let r1 = (r0 + BLOCK).min(h);
        for c in 0..w {
            let src = c * h;
            for r in r0..r1 {
                let (p, i, k) = (xyz[src + r], intensity[src + r], rgb[src + r]);
                dense &= p.iter().all(|v| v.is_finite());
                let words = [p[0].to_bits(), p[1].to_bits(), p[2].to_bits(), i.to_bits(), k];
                let at = (r * w + c) * step;
                for (dst, v) in data[at..at + step].chunks_exact_mut(4).zip(words) {
                    dst.copy_from_slice(&v.to_le_bytes());
                }
            }
        }
    }
    Some(cloud(header, height, width, data, dense))
}

/// The `x y z intensity rgb` cloud around `data`.
fn cloud(header: Header, height: u32, width: u32, data: Vec<u8>, dense: bool) -> PointCloud2 {
    let field = |name: &str, offset| PointField { name: name.into(), offset, datatype: PointField::FLOAT32, count: 1 };
    PointCloud2 {
        header,
        height,
        width,
        fields: vec![field("x", 0), field("y", 4), field("z", 8), field("intensity", 12), field("rgb", 16)],
        is_bigendian: false,
        point_step: POINT_STEP,
        row_step: POINT_STEP * width,
        data,
        is_dense: dense,
    }
}

/// Checks a cloud's sizes and fields and returns its points row by row (any field layout with
/// FLOAT32 `x y z`; `intensity` and `rgb` when present).
pub fn read(cloud: &PointCloud2) -> Result<Vec<CloudPoint>, CloudError> {
    if cloud.is_bigendian {
        return Err(CloudError::BigEndian);
    }
    let (w, h, ps, rs) =
        (cloud.width as usize, cloud.height as usize, cloud.point_step as usize, cloud.row_step as usize);
    let size_err = || CloudError::Size {
        width: cloud.width,
        height: cloud.height,
        point_step: cloud.point_step,
        row_step: cloud.row_step,
        len: cloud.data.len(),
    };
    if rs < w * ps || rs.checked_mul(h).is_none_or(|need| need > cloud.data.len()) || (h > 0 && w > 0 && ps == 0) {
        return Err(size_err());
    }
    let offset = |name: &'static str, required: bool| -> Result<Option<usize>, CloudError> {
        match cloud.fields.iter().find(|f| f.name == name) {
            Some(f) if f.datatype == PointField::FLOAT32 || (name == "rgb" && f.datatype == PointField::UINT32) => {
                if f.offset as usize + 4 > ps {
                    return Err(CloudError::FieldOutside {
                        name: f.name.clone(),
                        offset: f.offset,
                        point_step: cloud.point_step,
                    });
                }
                Ok(Some(f.offset as usize))
            }
            Some(_) => Err(CloudError::Field(name)),
            None if required => Err(CloudError::Field(name)),
            None => Ok(None),
        }
    };
    let (ox, oy, oz) = (offset("x", true)?, offset("y", true)?, offset("z", true)?);
    let (oi, oc) = (offset("intensity", false)?, offset("rgb", false)?);
    let f = |b: &[u8], o: usize| f32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]);
    let mut out = Vec::with_capacity(w * h);
    for r in 0..h {
        for c in 0..w {
            let b = &cloud.data[r * rs + c * ps..r * rs + (c + 1) * ps];
            out.push(CloudPoint {
                xyz: [f(b, ox.unwrap_or(0)), f(b, oy.unwrap_or(0)), f(b, oz.unwrap_or(0))],
                intensity: oi.map(|o| f(b, o)),
                rgb: oc.map(|o| f(b, o).to_bits()),
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn build_then_read_round_trips_with_nan() {
        let c = build(Header::default(), 2, 3, |r, c| {
            if r == 1 && c == 2 {
                ([f32::NAN; 3], 0.0, 0)
            } else {
                ([r as f32, c as f32, 0.5], 10.0, 0x00ff8000)
            }
        });
        assert_eq!(c.data.len(), 2 * 3 * 20);
        assert!(!c.is_dense);
        let p = read(&c).unwrap();
        assert_eq!(p[4].xyz, [1.0, 1.0, 0.5]);
        assert_eq!(p[4].rgb, Some(0x00ff8000));
        assert!(p[5].xyz[0].is_nan());
    }

    #[test]
    fn columns_give_the_same_cloud_as_points() {
        for (h, w) in [(1, 1), (17, 3), (33, 40), (5, 0)] {
            let n = (h * w) as usize;
            let at = |r: usize, c: usize| c * h as usize + r;
            let xyz: Vec<[f32; 3]> =
                (0..n).map(|i| if i % 7 == 3 { [f32::NAN; 3] } else { [i as f32, -(i as f32), 0.25] }).collect();
            let intensity: Vec<f32> = (0..n).map(|i| i as f32 * 0.5).collect();
            let rgb: Vec<u32> = (0..n as u32).map(|i| i * 0x010203).collect();
            let a = build_from_columns(Header::default(), h, w, &xyz, &intensity, &rgb).unwrap();
            let b = build(Header::default(), h, w, |r, c| (xyz[at(r, c)], intensity[at(r, c)], rgb[at(r, c)]));
            assert_eq!(a, b, "{h} x {w}");
        }
        assert!(build_from_columns(Header::default(), 2, 2, &[[0.0; 3]; 3], &[0.0; 4], &[0; 4]).is_none());
    }

    #[test]
    fn malformed_clouds_are_refused() {
        let mut c = build(Header::default(), 1, 2, |_, _| ([0.0; 3], 0.0, 0));
        c.data.pop();
        assert!(matches!(read(&c), Err(CloudError::Size { .. })));
        let mut c = build(Header::default(), 1, 2, |_, _| ([0.0; 3], 0.0, 0));
        c.fields.retain(|f| f.name != "z");
        assert_eq!(read(&c), Err(CloudError::Field("z")));
        let mut c = build(Header::default(), 1, 2, |_, _| ([0.0; 3], 0.0, 0));
        c.fields[0].offset = 18;
        assert!(matches!(read(&c), Err(CloudError::FieldOutside { .. })));
    }
}
