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
    /// The laser that lit it (an index into the `lasers` parameter), if the cloud has it.
    pub laser: Option<f32>,
    /// The line of its laser that placed it (0 the first, 1 a second surface's), if the cloud
    /// has the field `layer`.
    pub layer: Option<f32>,
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
    build_fields(header, height, width, (false, false), |r, c| {
        let (p, i, rgb) = point(r, c);
        (p, i, rgb, 0.0, 0.0)
    })
}

/// The same with a fourth field `laser` (FLOAT32, the index into the `lasers` parameter of the
/// laser that lit the point): the clouds of a scanner with several lasers.
pub fn build_with_laser(
    header: Header,
    height: u32,
    width: u32,
    mut point: impl FnMut(usize, usize) -> ([f32; 3], f32, u32, f32),
) -> PointCloud2 {
    build_fields(header, height, width, (true, false), |r, c| {
        let (p, i, rgb, l) = point(r, c);
        (p, i, rgb, l, 0.0)
    })
}

/// `x y z intensity rgb`, then the field `laser` where `laser` is set and the field `layer`
/// (FLOAT32, 0 for a laser's first line, 1 for its second surface's) where `layer` is set:
/// the clouds whose rows hold two lines per laser.
pub fn build_tagged(
    header: Header,
    height: u32,
    width: u32,
    (laser, layer): (bool, bool),
    point: impl FnMut(usize, usize) -> ([f32; 3], f32, u32, f32, f32),
) -> PointCloud2 {
    build_fields(header, height, width, (laser, layer), point)
}

/// True when `cloud` has the field `layer`: its rows hold each laser's first line, then each
/// laser's second (see [`build_tagged`]).
pub fn has_layers(cloud: &PointCloud2) -> bool {
    cloud.fields.iter().any(|f| f.name == "layer")
}

fn build_fields(
    header: Header,
    height: u32,
    width: u32,
    (laser, layer): (bool, bool),
    mut point: impl FnMut(usize, usize) -> ([f32; 3], f32, u32, f32, f32),
) -> PointCloud2 {
    let step = POINT_STEP + 4 * (u32::from(laser) + u32::from(layer));
    let n = height as usize * width as usize;
    let mut data = Vec::with_capacity(n * step as usize);
    let mut dense = true;
    for r in 0..height as usize {
        for c in 0..width as usize {
            let (p, i, rgb, l, k) = point(r, c);
            dense &= p.iter().all(|v| v.is_finite());
            for v in p {
                data.extend_from_slice(&v.to_le_bytes());
            }
            data.extend_from_slice(&i.to_le_bytes());
            data.extend_from_slice(&f32::from_bits(rgb).to_le_bytes());
            if laser {
                data.extend_from_slice(&l.to_le_bytes());
            }
            if layer {
                data.extend_from_slice(&k.to_le_bytes());
            }
        }
    }
    let field = |name: &str, offset| PointField { name: name.into(), offset, datatype: PointField::FLOAT32, count: 1 };
    let mut fields = vec![field("x", 0), field("y", 4), field("z", 8), field("intensity", 12), field("rgb", 16)];
    if laser {
        fields.push(field("laser", 20));
    }
    if layer {
        fields.push(field("layer", if laser { 24 } else { 20 }));
    }
    PointCloud2 {
        header,
        height,
        width,
        fields,
        is_bigendian: false,
        point_step: step,
        row_step: step * width,
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
    let (oi, oc, ol) = (offset("intensity", false)?, offset("rgb", false)?, offset("laser", false)?);
    let ok = offset("layer", false)?;
    let f = |b: &[u8], o: usize| f32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]);
    let mut out = Vec::with_capacity(w * h);
    for r in 0..h {
        for c in 0..w {
            let b = &cloud.data[r * rs + c * ps..r * rs + (c + 1) * ps];
            out.push(CloudPoint {
                xyz: [f(b, ox.unwrap_or(0)), f(b, oy.unwrap_or(0)), f(b, oz.unwrap_or(0))],
                intensity: oi.map(|o| f(b, o)),
                rgb: oc.map(|o| f(b, o).to_bits()),
                laser: ol.map(|o| f(b, o)),
                layer: ok.map(|o| f(b, o)),
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
        assert_eq!(p[4].laser, None);
        let c = build_with_laser(Header::default(), 2, 1, |r, _| ([r as f32; 3], 1.0, 7, r as f32));
        assert_eq!((c.point_step, c.fields.len()), (24, 6));
        let p = read(&c).unwrap();
        assert_eq!((p[1].xyz, p[1].rgb, p[1].laser), ([1.0; 3], Some(7), Some(1.0)));
        assert!(!has_layers(&c));
        // Two lines per laser: the field `layer` after `laser`.
        let c =
            build_tagged(Header::default(), 4, 1, (true, true), |r, _| ([r as f32; 3], 1.0, 7, 0.0, (r / 2) as f32));
        assert_eq!((c.point_step, c.fields.len(), c.fields[6].offset), (28, 7, 24));
        assert!(has_layers(&c));
        assert_eq!(f32::from_le_bytes(c.data[3 * 28 + 24..3 * 28 + 28].try_into().unwrap()), 1.0);
        assert_eq!((read(&c).unwrap()[3].laser, read(&c).unwrap()[3].layer), (Some(0.0), Some(1.0)));
        let c = build_tagged(Header::default(), 2, 1, (false, true), |r, _| ([r as f32; 3], 1.0, 7, 0.0, r as f32));
        assert_eq!((c.point_step, c.fields[5].name.as_str(), c.fields[5].offset), (24, "layer", 20));
        assert_eq!((read(&c).unwrap()[1].laser, read(&c).unwrap()[1].layer), (None, Some(1.0)));
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
