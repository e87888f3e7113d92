//! The one argument parser of the `xsurf` commands: flags, options with a value, positionals,
//! and groups that an option opens (`calibrate placement --camera cam1 --intrinsics c.yaml
//! a.png ...`). Every mistake is a [`UsageError`] that names the option.

use crate::UsageError;

/// A usage error (the binary prints the command's usage and exits 2).
pub fn usage(msg: impl Into<String>) -> anyhow::Error {
    anyhow::anyhow!(UsageError(msg.into()))
}

/// What a command takes.
#[derive(Debug, Clone, Copy, Default)]
pub struct Syntax<'a> {
    /// Options without a value (`--zstd`).
    pub flags: &'a [&'a str],
    /// Options with a value (`--out DIR`).
    pub valued: &'a [&'a str],
    /// The option that opens a group (`--camera NAME`) and the valued options that belong to the
    /// group last opened; positionals after a group belong to it.
    pub group: Option<(&'a str, &'a [&'a str])>,
}

/// A group of options opened by the group option: its value, its options and its positionals.
#[derive(Debug, Clone, Default)]
pub struct Group {
    /// The group option's value (the camera).
    pub name: String,
    opts: Vec<(String, String)>,
    /// Positionals after the group opened.
    pub positional: Vec<String>,
}

impl Group {
    /// The last value of `name` in the group.
    pub fn get(&self, name: &str) -> Option<&str> {
        self.opts.iter().rev().find(|(k, _)| k == name).map(|(_, v)| v.as_str())
    }
}

/// Parsed arguments.
#[derive(Debug, Clone, Default)]
pub struct Args {
    /// Positionals before any group.
    pub positional: Vec<String>,
    opts: Vec<(String, Option<String>)>,
    /// The groups, in order.
    pub groups: Vec<Group>,
}

/// A number an option takes, and how a wrong one is described.
pub trait Number: std::str::FromStr {
    /// What the option takes, in words.
    const KIND: &'static str;
    /// False for NaN and the infinities.
    fn finite(&self) -> bool {
        true
    }
}

impl Number for f64 {
    const KIND: &'static str = "a number";
    fn finite(&self) -> bool {
        self.is_finite()
    }
}

macro_rules! whole {
    ($kind:literal: $($t:ty),*) => {$(
        impl Number for $t {
            const KIND: &'static str = $kind;
        }
    )*};
}
whole!("a whole number, 0 or more": u8, u16, u32, u64, usize);
whole!("a whole number": i32, i64);

impl Args {
    /// Parses `args` as `syntax` says.
    pub fn parse(args: &[String], syntax: &Syntax) -> anyhow::Result<Args> {
        let mut a = Args::default();
        let mut i = 0;
        while i < args.len() {
            let s = args[i].as_str();
            let value = || args.get(i + 1).cloned().ok_or_else(|| usage(format!("{s} needs a value")));
            match syntax.group {
                Some((opener, _)) if s == opener => {
                    a.groups.push(Group { name: value()?, ..Group::default() });
                    i += 2;
                    continue;
                }
                Some((opener, inner)) if inner.contains(&s) => {
                    let v = value()?;
                    let g = a.groups.last_mut().ok_or_else(|| usage(format!("{s} belongs after {opener} NAME")))?;
                    g.opts.push((s.to_string(), v));
                    i += 2;
                    continue;
                }
                _ => {}
            }
            if syntax.valued.contains(&s) {
                a.opts.push((s.to_string(), Some(value()?)));
                i += 2;
            } else if syntax.flags.contains(&s) {
                a.opts.push((s.to_string(), None));
                i += 1;
            } else if s.starts_with('-') && s.len() > 1 {
                return Err(usage(format!("unknown option {s}")));
            } else {
                match a.groups.last_mut() {
                    Some(g) => g.positional.push(s.to_string()),
                    None => a.positional.push(s.to_string()),
                }
                i += 1;
            }
        }
        Ok(a)
    }

    /// The last value of `name`.
    pub fn get(&self, name: &str) -> Option<&str> {
        self.opts.iter().rev().find(|o| o.0 == name).and_then(|o| o.1.as_deref())
    }

    /// The last value of `name`, which the command needs.
    pub fn need(&self, name: &str) -> anyhow::Result<&str> {
        self.get(name).ok_or_else(|| usage(format!("{name} is required")))
    }

    /// True if the flag `name` was given.
    pub fn has(&self, name: &str) -> bool {
        self.opts.iter().any(|o| o.0 == name)
    }

    /// The number `name`, or `default` without it.
    pub fn num<T: Number>(&self, name: &str, default: T) -> anyhow::Result<T> {
        match self.get(name) {
            None => Ok(default),
            Some(v) => number(name, v),
        }
    }
}

/// `v`, the value of `name`, as a number.
pub fn number<T: Number>(name: &str, v: &str) -> anyhow::Result<T> {
    match v.trim().parse::<T>() {
        Ok(x) if x.finite() => Ok(x),
        Ok(_) => Err(usage(format!("{name}: {v:?} is not a finite number"))),
        Err(_) => Err(usage(format!("{name}: {v:?} is not {}", T::KIND))),
    }
}

/// A comma-separated list of finite numbers, the value of `name` (NaN and infinities are refused
/// by name).
pub fn list(name: &str, v: &str) -> anyhow::Result<Vec<f64>> {
    v.split(',')
        .map(|s| match s.trim().parse::<f64>() {
            Ok(x) if x.is_finite() => Ok(x),
            Ok(_) => Err(usage(format!("{name}: {s:?} in {v:?} is not a finite number"))),
            Err(_) => Err(usage(format!("{name}: {s:?} in {v:?} is not a number"))),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(s: &str) -> Vec<String> {
        s.split_whitespace().map(str::to_string).collect()
    }

    #[test]
    fn options_flags_positionals_and_groups() {
        let syntax = Syntax {
            flags: &["--zstd"],
            valued: &["-o", "--seed"],
            group: Some(("--camera", &["--intrinsics", "--travels"])),
        };
        let a = Args::parse(
            &args("x -o out --zstd --camera cam1 --intrinsics c1.yaml a.png b.png --camera cam2 c.png --seed 3"),
            &syntax,
        )
        .unwrap();
        assert_eq!(a.positional, ["x"]);
        assert_eq!((a.get("-o"), a.has("--zstd"), a.num("--seed", 0u64).unwrap()), (Some("out"), true, 3));
        assert_eq!(a.groups.len(), 2);
        assert_eq!((a.groups[0].name.as_str(), a.groups[0].get("--intrinsics")), ("cam1", Some("c1.yaml")));
        assert_eq!(a.groups[0].positional, ["a.png", "b.png"]);
        assert_eq!(a.groups[1].positional, ["c.png"]);
        let err = |s: &str| Args::parse(&args(s), &syntax).unwrap_err().to_string();
        assert_eq!(err("--bogus"), "unknown option --bogus");
        assert_eq!(err("-o"), "-o needs a value");
        assert_eq!(err("--travels 1,2"), "--travels belongs after --camera NAME");
        let a = Args::parse(&args("--seed -1"), &syntax).unwrap();
        assert_eq!(
            a.num::<u64>("--seed", 0).unwrap_err().to_string(),
            "--seed: \"-1\" is not a whole number, 0 or more"
        );
        let a = Args::parse(&args("--seed nan"), &Syntax { valued: &["--seed"], ..Syntax::default() }).unwrap();
        assert_eq!(a.num("--seed", 0.0).unwrap_err().to_string(), "--seed: \"nan\" is not a finite number");
        assert_eq!(list("--heights", "0, 1.5").unwrap(), [0.0, 1.5]);
        assert!(list("--heights", "0,NaN").unwrap_err().to_string().contains("is not a finite number"));
    }
}
