//! The scanner's lasers from a node's parameters (the spec's "Several laser planes"): the list
//! `lasers` and, per name, `laser.<name>.plane` (`double[4]`, nx ny nz d in `carm`, unit normal),
//! `laser.<name>.source` (`double[3]`, in `carm`) and `laser.<name>.channel` (red, green or blue),
//! as nav2 declares its plugin lists. Every node that needs them (camera_driver, edge_detector,
//! triangulator, mesher, merger) declares `lasers`; the per-laser names follow from it and are
//! read here, checked once (`core::rig::validate_lasers`), with errors that name the parameter.
//! Without `lasers` the single plane `laser_plane` is the whole scanner, as before.

use xsurf_core::edge::LaserColor;
use xsurf_core::rig::{validate_lasers, RigLaser};
use xsurf_runtime::params::{ParamError, ParamValue, Params};

/// The meaning of `lasers`, for the nodes' declarations.
pub const LASERS_DOC: &str = "the scanner's lasers by name (empty: the single laser_plane); each \
    needs laser.<name>.plane (double[4] nx ny nz d in carm, unit normal), laser.<name>.channel \
    (red, green or blue; each laser its own) and may give laser.<name>.source (double[3] in carm)";

/// The lasers named in `names`, read from `p`; `None` without any (the single `laser_plane`).
/// A laser's source defaults to `default_source` (the node's `laser_source`, where it has one);
/// its channel to red when it is the only laser.
pub fn from_params(
    p: &Params,
    names: &[String],
    default_source: [f64; 3],
) -> Result<Option<Vec<RigLaser>>, ParamError> {
    if names.is_empty() {
        return Ok(None);
    }
    let mut lasers = Vec::with_capacity(names.len());
    for name in names {
        let key = |field: &str| format!("laser.{name}.{field}");
        let plane = numbers(p, &key("plane"), 4, None)?;
        let source = numbers(p, &key("source"), 3, Some(&default_source))?;
        let channel = match p.get(&key("channel")) {
            Some(ParamValue::String(s)) => LaserColor::parse(s)
                .ok_or_else(|| Params::invalid(&key("channel"), format!("{s:?} is not red, green or blue")))?,
            Some(v) => {
                return Err(Params::invalid(&key("channel"), format!("{v} is not a string (red, green or blue)")))
            }
            None if names.len() == 1 => LaserColor::Red,
            None => {
                return Err(Params::invalid(
                    &key("channel"),
                    "not set: with several lasers each needs its colour (red, green or blue)",
                ))
            }
        };
        lasers.push(RigLaser {
            name: name.clone(),
            plane: [plane[0], plane[1], plane[2], plane[3]],
            source: [source[0], source[1], source[2]],
            channel,
        });
    }
    validate_lasers(&lasers).map_err(|e| {
        let (name, reason) = e.split_once(": ").unwrap_or(("lasers", &e));
        Params::invalid(name, reason.to_string())
    })?;
    Ok(Some(lasers))
}

/// `len` finite numbers from parameter `name`, or `default` when it is not set.
fn numbers(p: &Params, name: &str, len: usize, default: Option<&[f64]>) -> Result<Vec<f64>, ParamError> {
    let v: Vec<f64> = match p.get(name) {
        Some(ParamValue::DoubleArray(v)) => v.clone(),
        Some(ParamValue::IntegerArray(v)) => v.iter().map(|&i| i as f64).collect(),
        Some(v) => return Err(Params::invalid(name, format!("{v} is not a list of {len} numbers"))),
        None => match default {
            Some(d) => d.to_vec(),
            None => return Err(Params::invalid(name, "not set: each laser in `lasers` needs it")),
        },
    };
    if v.len() != len || !v.iter().all(|x| x.is_finite()) {
        return Err(Params::invalid(name, format!("{v:?} is not {len} finite numbers")));
    }
    Ok(v)
}

/// The parameters that give `lasers` to every node, as a params file's `/**` section holds them
/// (`lasers:=[...]` and each laser's `plane`, `source`, `channel`), for the files that
/// `xsurf synth` and `xsurf calibrate laser` write.
pub fn params_yaml(lasers: &[RigLaser]) -> String {
    let list = |v: &[f64]| v.iter().map(|x| format!("{x}")).collect::<Vec<_>>().join(", ");
    let mut s = format!("    lasers: [{}]\n", lasers.iter().map(|l| l.name.as_str()).collect::<Vec<_>>().join(", "));
    for l in lasers {
        s.push_str(&format!("    laser.{}.plane: [{}]\n", l.name, list(&l.plane)));
        s.push_str(&format!("    laser.{}.source: [{}]\n", l.name, list(&l.source)));
        s.push_str(&format!("    laser.{}.channel: {}\n", l.name, l.channel.name()));
    }
    s
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use std::collections::BTreeMap;

    /// Parameter overrides, by name.
    type Overrides = Vec<(&'static str, ParamValue)>;

    fn params(extra: &[(&str, ParamValue)]) -> Params {
        let mut o: BTreeMap<String, ParamValue> = BTreeMap::new();
        for (k, v) in extra {
            o.insert((*k).to_string(), v.clone());
        }
        Params::resolve(&[], &o).unwrap()
    }

    fn three() -> Overrides {
        let rig = xsurf_core::rig::Rig::three_lasers(640, 480);
        let mut v = Vec::new();
        for (l, name) in rig.lasers.iter().zip(["collimator", "left", "right"]) {
            let key = |f: &str| -> &'static str { Box::leak(format!("laser.{name}.{f}").into_boxed_str()) };
            v.push((key("plane"), ParamValue::DoubleArray(l.plane.to_vec())));
            v.push((key("source"), ParamValue::DoubleArray(l.source.to_vec())));
            v.push((key("channel"), ParamValue::String(l.channel.name().into())));
        }
        v
    }

    fn names() -> Vec<String> {
        ["collimator", "left", "right"].map(String::from).to_vec()
    }

    #[test]
    fn three_lasers_read_and_written_back() {
        let rig = xsurf_core::rig::Rig::three_lasers(640, 480);
        let got = from_params(&params(&three()), &names(), [0.0; 3]).unwrap().unwrap();
        assert_eq!(got, rig.lasers);
        // The params text reads back as the same lasers.
        let yaml = format!("/**:\n  ros__parameters:\n{}", params_yaml(&rig.lasers));
        let o = xsurf_runtime::rosargs::params_from_yaml(&yaml, "/cam1/edge_detector").unwrap();
        let p = Params::resolve(&[], &o).unwrap();
        assert_eq!(from_params(&p, &names(), [0.0; 3]).unwrap().unwrap(), rig.lasers);
        assert_eq!(from_params(&p, &[], [0.0; 3]).unwrap(), None);
    }

    /// Each misconfiguration the spec names is an error naming its parameter.
    #[test]
    fn bad_lasers_name_their_parameter() {
        let bad = |change: &dyn Fn(&mut Overrides), names: &[String], says: &str| {
            let mut v = three();
            change(&mut v);
            let e = from_params(&params(&v), names, [0.0; 3]).unwrap_err().to_string();
            assert!(e.contains(says), "{says}: {e}");
        };
        let set = |k: &'static str, val: ParamValue| {
            move |v: &mut Overrides| {
                v.retain(|(n, _)| *n != k);
                v.push((k, val.clone()));
            }
        };
        bad(&set("laser.left.channel", ParamValue::String("red".into())), &names(), "laser.left.channel");
        bad(
            &set("laser.right.plane", ParamValue::DoubleArray(vec![0.0, 2.0, 0.0, 0.0])),
            &names(),
            "laser.right.plane",
        );
        bad(&set("laser.right.plane", ParamValue::DoubleArray(vec![0.0, 1.0])), &names(), "laser.right.plane");
        bad(&|v| v.retain(|(n, _)| *n != "laser.left.plane"), &names(), "laser.left.plane");
        bad(&|v| v.retain(|(n, _)| *n != "laser.left.channel"), &names(), "laser.left.channel");
        bad(&set("laser.left.channel", ParamValue::String("violet".into())), &names(), "laser.left.channel");
        let mut four = names();
        four.push("extra".into());
        bad(&|_| {}, &four, "laser.extra.plane");
        bad(&|_| {}, &["collimator".into(), "collimator".into()], "listed twice");
    }
}
