//! The `xsurf` command (`nodes/src/bin/xsurf.rs` calls [`main`]): the offline tools, bags,
//! parameters, calibration, composition and launch.
//!
//! ```text
//! xsurf demo [--out DIR] [--scene NAME] [--size WxH] [--speed M_S] [--preset ideal|hard] [--encoding E]
//! xsurf synth SCENE -o DIR [--size WxH | --rig FILE] [--speed M_S] [--fps F] [--encoding E] [--seed N] [--preset ideal|hard] [--zstd] [--horizontal CAMS]
//! xsurf reconstruct BAG [--params-file FILE] [--xray FILE.dcm] [--pacs AET@HOST:PORT] --out DIR
//! xsurf pacs echo AET@HOST:PORT | send FILE|DIR AET@HOST:PORT [--ae-title T]
//! xsurf bag info DIR
//! xsurf bag reindex DIR [--force]
//! xsurf bag record -o DIR [TOPIC... | --all] [--zstd] [--split-by-scan] [--duration S]
//! xsurf bag play DIR [--rate R] [--loop] [--clock] [--topics T1,T2] [--start-offset S] [--delay S]
//! xsurf param list NODE | get NODE NAME | set NODE NAME VALUE [--timeout S]
//! xsurf calibrate synth|intrinsics|placement|laser ...
//! xsurf compose /NS/NODE_TYPE... [--ros-args ...]
//! ```
//! Only `bag record`, `bag play`, `param` and `compose` open a DDS participant.

use crate::{offline, synth, UsageError};
use anyhow::{anyhow, Context};
use args::{usage, Args, Syntax};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use xsurf_core::eval;
use xsurf_core::image::Encoding;
use xsurf_core::rig::Rig;
use xsurf_core::synth::{Preset, ScanSettings, Scanner, Scene, SCENE_NAMES};

pub mod args;
pub mod calibrate;

const USAGE: &str = "usage:
  xsurf demo [--out DIR] [--scene NAME] [--size WxH] [--speed M_S] [--preset ideal|hard] [--encoding E]
      synthesize a scan, reconstruct it, write the files and report the accuracy (default out: ./xsurf-demo)
  xsurf synth SCENE -o DIR [--size WxH | --rig FILE] [--speed M_S] [--fps F] [--encoding mono8|rgb8|bgr8] [--seed N] [--preset ideal|hard] [--zstd] [--frames N] [--lasers 1|3] [--horizontal CAMS]
             [--compressed jpeg|png [--jpeg-quality Q]]
      write a synthetic scan as a rosbag2 bag plus its ground truth and radiograph (scenes: pyramid, phantom,
      sphere, cylinder, box, body); with --compressed the cameras are sensor_msgs/CompressedImage on
      /<cam>/image_raw/compressed (JPEG quality default 90); with --frames N, N frames per camera as PGM files
      instead (DIR/<camera>/; JPEG or PNG files with --compressed)
  xsurf reconstruct BAG [--params-file FILE] [--xray FILE.dcm] [--pacs AET@HOST:PORT] --out DIR
      reconstruct a recorded scan offline: DIR/<cam>.ply, merged.ply, scene.wrl, scene.glb, surface.dcm,
      report.json; with --pacs the DICOM files go to the PACS (queued in DIR/pacs_queue if it does not take them)
  xsurf pacs echo AET@HOST:PORT [--ae-title T]
      DICOM C-ECHO: does the PACS answer us?
  xsurf pacs send FILE|DIR AET@HOST:PORT [--ae-title T]
      DICOM C-STORE of a file, or of every .dcm file under a folder; a PACS queue folder (pacs_queue)
      is emptied, each scan removed once stored
  xsurf bag info DIR
      summarize a bag, like `ros2 bag info`
  xsurf bag reindex DIR [--force]
      write the metadata.yaml of a bag folder that has none, from its .mcap files (as `ros2 bag reindex`)
  xsurf bag record -o DIR [TOPIC... | --all] [--zstd] [--split-by-scan] [--duration S]
      record topics from DDS into a bag (QoS recorded per topic); stops on Ctrl-C or after S
  xsurf bag play DIR [--rate R] [--loop] [--clock] [--topics T1,T2] [--start-offset S] [--delay S]
      publish a bag over DDS with its original timing (honours ROS_DOMAIN_ID, ROS_LOCALHOST_ONLY)
  xsurf param list NODE | get NODE NAME | set NODE NAME VALUE [--timeout S]
      a node's parameters through the standard ROS 2 parameter services (like `ros2 param`)
  xsurf calibrate synth DIR [--size WxH] [--board COLSxROWS] [--square M] [--views N] [--noise S] [--seed N]
                        [--preset ideal|hard]
      render a calibration set with known truth (board views, board on the tabletop, laser at 3 heights)
      and DIR/calibrate.sh, the commands below that calibrate from it
  xsurf calibrate intrinsics IMAGE... --board COLSxROWS --square M -o CAMERA.yaml [--name N]
        [--model plumb_bob|rational_polynomial] [--report DIR]
      checkerboard views -> camera_calibration YAML (camera_info_url); per-image errors, outliers rejected
  xsurf calibrate placement [--rig RIG] -o RIG --board COLSxROWS --square M --board-origin X,Y[,Z] [--board-yaw DEG]
        (--camera NAME --intrinsics CAMERA.yaml --travels T[,T...] IMAGE...)... [--report DIR]
      the board flat on the tabletop (corner 0 at X,Y in `table`) -> carm -> <cam>_optical_frame in the rig
  xsurf calibrate laser --rig RIG [-o RIG] (--camera NAME --heights H[,H...] IMAGE...)... [--report DIR]
      the laser line on the tabletop at two or more heights -> laser_plane in the rig
  xsurf calibrate scan BAG --rig RIG [-o RIG] [--params-file FILE] [--max-translation M] [--max-rotation DEG] [--report DIR]
      each further camera's placement refined against the first camera's surface in a scan of any
      rigid object both cameras see (the study's pyramid, say); no hand input
      (every calibrate command writes report.json and PNG plots to DIR, default <output>_<command>_report/)
  xsurf compose /NS/NODE_TYPE... | /NS/NAME=NODE_TYPE... [--ros-args ...]
      run several nodes in one process, connected in memory, every topic still on DDS
  xsurf launch FILE [--composed] [NAME:=VALUE...]
      start the nodes of a ROS 2 YAML launch file, one process each (or all in one with --composed);
      a node that dies stops the others and the launcher exits 1";

/// The usage of one command (`xsurf bag info --help`: that block; `xsurf bag --help`: every
/// `bag` block), or the whole usage when `args` names no command.
/// Per command: its options explained, with defaults and units, and an example. Shown by
/// `xsurf CMD --help` and after a usage error of that command, below its usage line.
const DETAILS: &[(&str, &str)] = &[
    ("demo", "options:
  --out DIR          where the bag and the reconstruction go (default ./xsurf-demo)
  --scene NAME       pyramid (default), phantom, sphere, cylinder, box or body
  --size WxH         each camera's image, pixels (default 640x480; 32 to 8192 a side)
  --speed M_S        the C-arm's speed, m/s (default 0.07; above 0, below 2)
  --preset P         ideal (default) or hard: noise, blur, uneven light and dark surfaces
  --encoding E       mono8 (default), rgb8 or bgr8
  --lasers N         1 (default) or 3: the collimator's plane and two tilted planes (rgb8 or bgr8)
example: xsurf demo --out /tmp/demo --scene phantom"),
    ("synth", "options:
  SCENE              pyramid, phantom, sphere, cylinder, box or body
  -o DIR             the bag folder to write (written under a temporary name, renamed when complete)
  --size WxH         each camera's image, pixels (default 640x480), or --rig FILE for a rig file's cameras
  --speed M_S        the C-arm's speed, m/s (default 0.07)     --fps F   frames per second (default 30)
  --encoding E       mono8 (default), rgb8 or bgr8             --seed N  noise seed, 0 or more (default 1)
  --preset P         ideal (default) or hard                   --zstd    compress the bag's chunks
  --compressed F     jpeg or png: sensor_msgs/CompressedImage; --jpeg-quality Q, 1 to 100 (default 90)
  --frames N         N frames per camera as image files instead of a bag
  --lasers N         1 (default: the collimator's plane) or 3 (and green and blue planes tilted 25
                     degrees, cameras at 45 degrees: Rig::three_lasers; needs rgb8 or bgr8)
  --horizontal CAMS  these cameras (cam2, or cam1,cam2) hung on their side, a quarter turn about
                     the optical axis: their line runs along the rows (params.yaml says so)
example: xsurf synth phantom -o /tmp/phantom-bag --preset hard --zstd"),
    ("reconstruct", "options:
  BAG                a rosbag2 folder (MCAP): images or compressed images, camera_info, /tf, /tf_static
  --out DIR          where the surfaces go; an earlier reconstruction's own files there are replaced
  --params-file FILE the nodes' parameters (ROS 2 YAML, as for `ros2 run --params-file`)
  --xray FILE.dcm    the radiograph to place under the surface; surface.dcm joins its patient and study
  --pacs AET@HOST:PORT  send the DICOM files (surface.dcm, xray.dcm) to this PACS; what it does not
                     take waits in DIR/pacs_queue (exit 1), for `xsurf pacs send DIR/pacs_queue ADDR`
  --ae-title T       our AE title towards the PACS (default XSURF)
  --quiet            no progress
exit codes: 0 done, 1 failed, 2 usage, 3 files written but the result is incomplete (see report.json)
example: xsurf reconstruct /tmp/phantom-bag --xray /tmp/phantom-bag/xray.dcm --out /tmp/phantom"),
    ("pacs echo", "options:
  AET@HOST:PORT      the PACS: its AE title, host and port (DICOM's standard port is 104)
  --ae-title T       our AE title (default XSURF)
example: xsurf pacs echo ORTHANC@127.0.0.1:4242"),
    ("pacs send", "options:
  FILE|DIR           a DICOM file, a folder (every .dcm file under it), or a PACS queue folder
                     (each scan in it removed once the PACS has stored it)
  AET@HOST:PORT      the PACS                         --ae-title T   our AE title (default XSURF)
exit codes: 0 every file stored, 1 not (what failed, naming the PACS, the SOP class and the status)
example: xsurf pacs send /data/scans/pacs_queue ORTHANC@127.0.0.1:4242"),
    ("bag info", "example: xsurf bag info /tmp/phantom-bag"),
    ("bag reindex", "options:
  DIR                a folder of <name>_<N>.mcap files (split files of a killed recorder, say)
  --force            replace an existing metadata.yaml
example: xsurf bag reindex /tmp/rec && xsurf bag info /tmp/rec"),
    ("bag record", "options:
  -o DIR             the bag folder to write          TOPIC... or --all   what to record
  --zstd             compress the chunks              --duration S        stop after S seconds
  --split-by-scan    one bag per scan, DIR/scan_<id> (START to END, from /scan/events; each
                     begins with the last /tf_static and /tf; nothing between scans)
example: xsurf bag record -o /tmp/rec /surface/cloud /surface/mesh /tf --duration 30
         xsurf bag record -o /data/scans --split-by-scan /cam1/image_raw /cam1/camera_info"),
    ("bag play", "options:
  --rate R           speed factor (default 1)         --loop              start again at the end
  --clock            publish /clock (for use_sim_time) --topics T1,T2     only these topics
  --start-offset S   skip the first S seconds         --delay S           wait S seconds for subscribers first (default 1)
example: ROS_LOCALHOST_ONLY=1 xsurf bag play /tmp/phantom-bag --clock"),
    ("param", "options:
  NODE               the fully qualified node name, e.g. /cam1/edge_detector
  --timeout S        how long to wait for the node's parameter services (default 15)
example: xsurf param set /cam1/edge_detector min_strength 20"),
    ("calibrate synth", "options:
  DIR                the folder for the set (board views, tabletop views, laser lines, calibrate.sh, truth_rig.yaml)
  --size WxH         image size (default 640x480)     --board COLSxROWS   inner corners (default 9x6)
  --square M         square side, m (default 0.02765) --views N           board views per camera, 3 to 500 (default 20)
  --noise S          image noise, grey levels (default 2)  --seed N       0 or more (default 1)
  --preset P         ideal (default) or hard (shadows, glare, blur, JPEG)
example: xsurf calibrate synth /tmp/calset && bash /tmp/calset/calibrate.sh"),
    ("calibrate intrinsics", "options:
  IMAGE...           board views (PNG, JPEG or PGM)   --board COLSxROWS --square M   the board (inner corners, m)
  -o CAMERA.yaml     the camera_calibration YAML      --name N            the camera's name (default: the file's stem)
  --model M          plumb_bob (default) or rational_polynomial
  --report DIR       report.json and plots (default <output>_intrinsics_report/)
example: xsurf calibrate intrinsics views/cam1_*.png --board 9x6 --square 0.02765 -o cam1.yaml"),
    ("calibrate placement", "options:
  --board-origin X,Y[,Z]  corner 0 of the board on the tabletop, in `table`, m   --board-yaw DEG   its turn (default 0)
  per camera: --camera NAME --intrinsics CAMERA.yaml --travels T[,T...] IMAGE... (one travel, m, per image)
example: xsurf calibrate placement --board 9x6 --square 0.02765 --board-origin -0.11,0.07 -o rig.yaml \\
           --camera cam1 --intrinsics cam1.yaml --travels 0,0.03 p/cam1_0.png p/cam1_1.png"),
    ("calibrate laser", "options:
  --rig RIG          the rig with the cameras placed   -o RIG             where to write it (default: --rig)
  per camera: --camera NAME --heights H[,H...] IMAGE... (the tabletop's height, m, per image)
example: xsurf calibrate laser --rig rig.yaml --camera cam1 --heights 0,0.05,0.1 l/cam1_0.png l/cam1_1.png l/cam1_2.png"),
    ("launch", "options:
  FILE               a ROS 2 YAML launch file (node: pkg, exec, name, namespace, param, remap; arg; let)
  --composed         all nodes in one process, connected in memory
  NAME:=VALUE        a launch argument
example: xsurf launch launch-config/xsurf.launch.yaml params:=launch-config/params.yaml"),
    ("calibrate scan", "options:
  --max-translation M  refuse a correction beyond this, m   --max-rotation DEG   or beyond this turn
example: xsurf calibrate scan /tmp/pyramid-bag --rig rig.yaml -o rig.yaml"),
];

fn command_usage(args: &[String]) -> String {
    let words: Vec<&str> = args.iter().map(String::as_str).take_while(|a| !a.starts_with('-')).collect();
    let mut blocks: Vec<Vec<&str>> = Vec::new();
    for line in USAGE.lines().skip(1) {
        if line.starts_with("  xsurf ") {
            blocks.push(vec![line]);
        } else if let Some(b) = blocks.last_mut() {
            b.push(line);
        }
    }
    let head = |b: &Vec<&str>| {
        b[0].trim_start().trim_start_matches("xsurf ").split_whitespace().map(str::to_string).collect::<Vec<_>>()
    };
    for n in (1..=words.len()).rev() {
        let chosen: Vec<&Vec<&str>> = blocks
            .iter()
            .filter(|b| {
                let h = head(b);
                h.len() >= n && h[..n].iter().zip(&words[..n]).all(|(a, w)| a.split('|').any(|x| x == *w))
            })
            .collect();
        if !chosen.is_empty() {
            let body: Vec<String> = chosen.iter().map(|b| b.join("\n")).collect();
            // One command chosen: its options and an example too.
            let detail = match chosen.as_slice() {
                [b] => {
                    let h = head(b);
                    DETAILS
                        .iter()
                        .find(|(cmd, _)| {
                            let c: Vec<&str> = cmd.split(' ').collect();
                            h.len() >= c.len() && h.iter().zip(&c).all(|(a, w)| a.split('|').next() == Some(*w))
                        })
                        .map(|(_, d)| format!("\n{d}\n"))
                        .unwrap_or_default()
                }
                _ => String::new(),
            };
            return format!(
                "usage:\n{}\n{detail}\n(all commands: xsurf --help; version: xsurf --version)",
                body.join("\n")
            );
        }
    }
    USAGE.to_string()
}

/// Writes to standard output without panicking when the reader has gone (`xsurf --help | head`).
fn write_stdout(text: &str) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    let _ = out.write_all(text.as_bytes()).and_then(|()| out.flush());
}

fn size(a: &Args) -> anyhow::Result<(u32, u32)> {
    let s = a.get("--size").unwrap_or("640x480");
    let (w, h) = s.split_once('x').ok_or_else(|| usage(format!("--size {s}: expected WxH")))?;
    let (w, h): (u32, u32) =
        (w.parse().map_err(|_| usage("--size: bad width"))?, h.parse().map_err(|_| usage("--size: bad height"))?);
    if !xsurf_core::limits::image_side_ok(w) || !xsurf_core::limits::image_side_ok(h) {
        return Err(usage(format!(
            "--size {s}: width and height must be in {}",
            xsurf_core::limits::image_side_text()
        )));
    }
    Ok((w, h))
}

fn scanner(a: &Args, scene: &str) -> anyhow::Result<Scanner> {
    let scene = Scene::by_name(scene)
        .ok_or_else(|| usage(format!("unknown scene {scene:?} (known: {})", SCENE_NAMES.join(", "))))?;
    let (w, h) = size(a)?;
    let encoding = match a.get("--encoding").unwrap_or("mono8") {
        "mono8" => Encoding::Mono8,
        "rgb8" => Encoding::Rgb8,
        "bgr8" => Encoding::Bgr8,
        other => return Err(usage(format!("--encoding {other}: expected mono8, rgb8 or bgr8"))),
    };
    let preset = match a.get("--preset") {
        None => Preset::Ideal,
        Some(p) => Preset::parse(p).ok_or_else(|| usage(format!("--preset {p}: expected ideal or hard")))?,
    };
    let mut settings = ScanSettings {
        speed_mps: a.num("--speed", 0.070)?,
        fps: a.num("--fps", 30.0)?,
        seed: a.num("--seed", 1u64)?,
        encoding,
        ..ScanSettings::default()
    };
    preset.apply(&mut settings);
    let mut rig = match a.get("--rig") {
        None if a.get("--lasers") == Some("3") => {
            if !encoding.is_color() {
                return Err(usage("--lasers 3: a grey camera cannot tell the lasers apart (--encoding rgb8 or bgr8)"));
            }
            Rig::three_lasers(w, h)
        }
        None => match a.get("--lasers") {
            None | Some("1") => Rig::study(w, h),
            Some(n) => return Err(usage(format!("--lasers {n}: 1 (the collimator) or 3 (and two tilted planes)"))),
        },
        Some(f) => {
            let rig = xsurf_formats::rig::read(Path::new(f)).with_context(|| format!("--rig {f}"))?;
            if a.get("--size").is_some() {
                return Err(usage("--size and --rig: the rig file gives each camera's image size"));
            }
            rig
        }
    };
    for name in a.get("--horizontal").into_iter().flat_map(|l| l.split(',')) {
        let known = rig.cameras.iter().map(|c| c.name.clone()).collect::<Vec<_>>().join(", ");
        let cam = rig
            .cameras
            .iter_mut()
            .find(|c| c.name == name)
            .ok_or_else(|| usage(format!("--horizontal {name}: no such camera (the rig has {known})")))?;
        cam.roll_quarter_turn();
    }
    // Before the scanner sets up (which at 8192x8192 alone takes seconds and gigabytes).
    synth::check_memory(&rig)?;
    Ok(Scanner::new(scene, rig, preset.laser(), settings)?)
}

fn progress_printer(label: &'static str) -> impl FnMut(u32, u32) {
    let mut last = std::time::Instant::now();
    move |done, total| {
        if done == total || last.elapsed().as_secs_f64() > 2.0 {
            last = std::time::Instant::now();
            eprintln!("{label}: {done}/{total} frames");
        }
    }
}

fn cmd_synth(args: &[String]) -> anyhow::Result<()> {
    let a = Args::parse(
        args,
        &Syntax {
            flags: &["--zstd"],
            valued: &[
                "-o",
                "--out",
                "--size",
                "--speed",
                "--fps",
                "--encoding",
                "--seed",
                "--rig",
                "--frames",
                "--preset",
                "--compressed",
                "--jpeg-quality",
                "--lasers",
                "--horizontal",
            ],
            group: None,
        },
    )?;
    let compressed = match a.get("--compressed") {
        None => None,
        Some(c) => {
            let codec = xsurf_formats::compressed::Codec::parse(c)
                .ok_or_else(|| usage(format!("--compressed {c:?}: jpeg or png")))?;
            let q = a.get("--jpeg-quality").unwrap_or("90");
            let q: u8 = q
                .parse()
                .ok()
                .filter(|q| (1..=100).contains(q))
                .ok_or_else(|| usage(format!("--jpeg-quality {q:?}: 1..=100")))?;
            Some((codec, q))
        }
    };
    let [scene] = a.positional.as_slice() else { return Err(usage("synth needs one SCENE")) };
    let out = a.get("-o").or(a.get("--out")).ok_or_else(|| usage("synth needs -o DIR"))?;
    let s = scanner(&a, scene)?;
    if let Some(n) = a.get("--frames") {
        let n: u32 = n.parse().map_err(|_| usage(format!("--frames {n}: not a count")))?;
        return write_frames(&s, Path::new(out), n, compressed);
    }
    let summary = synth::write_bag(Path::new(out), &s, a.has("--zstd"), 1, compressed, progress_printer("synth"))?;
    println!(
        "wrote {out}: scene {}, {} frames x {} cameras, {} messages; ground truth in {out}/truth.json",
        summary.scene,
        summary.frames,
        summary.cameras.len(),
        summary.messages
    );
    Ok(())
}

/// `synth --frames N`: image files for the camera_driver's files source, N frames from the
/// middle of the scan, PGM (mono8), or with `--compressed` JPEG or PNG files (any encoding).
fn write_frames(
    s: &Scanner,
    out: &Path,
    n: u32,
    compressed: Option<(xsurf_formats::compressed::Codec, u8)>,
) -> anyhow::Result<()> {
    let total = s.frame_count();
    let first = total.saturating_sub(n) / 2;
    let ext = match compressed {
        None => "pgm",
        Some((xsurf_formats::compressed::Codec::Jpeg, _)) => "jpg",
        Some((xsurf_formats::compressed::Codec::Png, _)) => "png",
    };
    for (ci, c) in s.rig.cameras.iter().enumerate() {
        let dir = out.join(&c.name);
        std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
        for f in first..(first + n).min(total) {
            let img = s.render(ci, f);
            let path = dir.join(format!("frame_{:04}.{ext}", f - first));
            match compressed {
                Some((codec, quality)) => {
                    let (_, bytes) =
                        xsurf_formats::compressed::encode(&img, codec, quality).map_err(anyhow::Error::msg)?;
                    xsurf_formats::write_bytes_atomic(&path, &bytes)?;
                }
                None => match img.encoding {
                    xsurf_core::image::Encoding::Mono8 | xsurf_core::image::Encoding::Mono16 => {
                        xsurf_formats::frames::write_pgm(&path, &img)?
                    }
                    _ => {
                        return Err(usage("--frames writes mono8 frames as PGM (colour: add --compressed jpeg or png)"))
                    }
                },
            }
        }
    }
    println!("wrote {} frames per camera as {}/<camera>/frame_NNNN.{ext}", n.min(total), out.display());
    Ok(())
}

fn cmd_reconstruct(args: &[String]) -> anyhow::Result<()> {
    let a = Args::parse(
        args,
        &Syntax {
            flags: &["--quiet"],
            valued: &["--params-file", "--xray", "--out", "-o", "--pacs", "--ae-title"],
            group: None,
        },
    )?;
    let pacs = match a.get("--pacs") {
        Some(addr) => {
            let peer: crate::pacs::Peer = addr.parse().map_err(|e| usage(format!("--pacs {e}")))?;
            let client = crate::pacs::Client::new(a.get("--ae-title").unwrap_or("XSURF"))
                .map_err(|e| usage(format!("--ae-title: {e}")))?;
            Some((peer, client))
        }
        None => None,
    };
    let [bag] = a.positional.as_slice() else { return Err(usage("reconstruct needs one BAG")) };
    let out = a.get("--out").or(a.get("-o")).ok_or_else(|| usage("reconstruct needs --out DIR"))?;
    let opts = offline::Options {
        bag: PathBuf::from(bag),
        params_file: a.get("--params-file").map(PathBuf::from),
        out: PathBuf::from(out),
        progress: !a.has("--quiet"),
        xray: a.get("--xray").map(PathBuf::from),
        ..Default::default()
    };
    let r = offline::reconstruct(&opts)?;
    print_report(&r, out);
    if let Some((peer, client)) = &pacs {
        send_scans(Path::new(out), peer, client)?;
    }
    let own = opts.bag.join(synth::XRAY_FILE);
    if opts.xray.is_none() && own.is_file() {
        println!(
            "  radiograph: not placed, none given; the bag holds one: --xray {} places it under the surface",
            own.display()
        );
    }
    let problems = r.problems();
    if !problems.is_empty() {
        return Err(anyhow!(Incomplete(problems)));
    }
    Ok(())
}

/// Queues the DICOM files of a reconstruction in `out` (one entry per scan folder, or `out`
/// itself for one scan) in `out/pacs_queue`, then sends the queue to `peer`.
fn send_scans(out: &Path, peer: &crate::pacs::Peer, client: &crate::pacs::Client) -> anyhow::Result<()> {
    let queue = crate::pacs::Queue::open(&out.join("pacs_queue"))?;
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(out)?
        .filter_map(Result::ok)
        .filter(|e| e.file_name().to_string_lossy().starts_with("scan_") && e.path().is_dir())
        .map(|e| e.path())
        .collect();
    dirs.sort();
    if dirs.is_empty() {
        dirs.push(out.to_path_buf());
    }
    let stamp = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_nanos()).unwrap_or(0);
    for d in &dirs {
        // A scan's folder holds no folders but a queue's, which dicom_files passes over.
        let files = crate::pacs::dicom_files(d);
        if files.is_empty() {
            continue;
        }
        let name = d.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        queue.enqueue(&format!("{stamp:020}-{name}"), &files)?;
    }
    send_queue(&queue, peer, client)
}

/// Sends every entry of `queue` to `peer`, oldest first; the first failure stops it, and what
/// is not sent stays queued.
fn send_queue(
    queue: &crate::pacs::Queue,
    peer: &crate::pacs::Peer,
    client: &crate::pacs::Client,
) -> anyhow::Result<()> {
    queue
        .send_all(client, peer, |entry, stored| {
            let files: Vec<_> = stored.iter().map(|s| crate::pacs::entry_name(&s.file)).collect();
            println!("pacs: {} stored in {peer}: {}", crate::pacs::entry_name(entry), files.join(", "));
        })
        .map_err(|failure| {
            let e = &failure.1;
            anyhow!(
                "{e}\n  not sent: {} scan(s) wait in {} (`xsurf pacs send {} {peer}` sends them)",
                queue.entries().len(),
                queue.dir().display(),
                queue.dir().display()
            )
        })
}

fn cmd_pacs(args: &[String]) -> anyhow::Result<()> {
    let a = Args::parse(args, &Syntax { flags: &[], valued: &["--ae-title"], group: None })?;
    let client = crate::pacs::Client::new(a.get("--ae-title").unwrap_or("XSURF"))
        .map_err(|e| usage(format!("--ae-title: {e}")))?;
    let peer = |s: &str| -> anyhow::Result<crate::pacs::Peer> { s.parse().map_err(|e: String| usage(e)) };
    match a.positional.iter().map(String::as_str).collect::<Vec<_>>().as_slice() {
        ["echo", addr] => {
            let p = peer(addr)?;
            crate::pacs::echo(&client, &p)?;
            println!("pacs: {p} answers C-ECHO (calling AE {})", client.calling);
            Ok(())
        }
        ["send", path, addr] => {
            let p = peer(addr)?;
            let path = Path::new(path);
            if let Some(why) = xsurf_formats::file_problem(path).filter(|_| !path.is_dir()) {
                return Err(anyhow!("{}: {why}", path.display()));
            }
            if crate::pacs::Queue::is_queue(path) {
                return send_queue(&crate::pacs::Queue::open(path)?, &p, &client);
            }
            let files = crate::pacs::dicom_files(path);
            if files.is_empty() {
                return Err(anyhow!("{}: no .dcm file to send", path.display()));
            }
            let stored = crate::pacs::store(&client, &p, &files)?;
            println!("pacs: {} file(s) stored in {p}", stored.len());
            Ok(())
        }
        _ => Err(usage("pacs echo AET@HOST:PORT | pacs send FILE|DIR AET@HOST:PORT")),
    }
}

/// The reconstruction ran but its input was partly bad: exit code 3, outputs kept.
#[derive(Debug)]
struct Incomplete(Vec<String>);
impl std::fmt::Display for Incomplete {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "the reconstruction is incomplete (files written, see report.json):\n  {}", self.0.join("\n  "))
    }
}
impl std::error::Error for Incomplete {}

fn print_report(r: &offline::Report, out: &str) {
    println!(
        "reconstructed {} ({} cameras, scans {:?}) in {:.2} s, {:.0} frames/s",
        r.bag,
        r.cameras.len(),
        r.scans,
        r.timings_s.get("total").copied().unwrap_or(0.0),
        r.frames_per_second
    );
    for c in &r.cameras {
        println!(
            "  {c}: {} frames read, {} with a line, {} points triangulated, {} in the surface ({} triangles), {} frames dropped",
            r.frames_read.get(c).unwrap_or(&0),
            r.frames_with_line.get(c).unwrap_or(&0),
            r.points.get(c).unwrap_or(&0),
            r.surface_points.get(c).unwrap_or(&0),
            r.triangles.get(c).unwrap_or(&0),
            r.dropped_frames.get(c).unwrap_or(&0)
        );
    }
    println!("  merged: {} points, {} triangles", r.merged_points, r.merged_triangles);
    if let Some(x) = &r.xray {
        println!("  radiograph: {x}");
    }
    println!("files in {out}: {}", r.files.join(", "));
}

fn cmd_demo(args: &[String]) -> anyhow::Result<()> {
    let a = Args::parse(
        args,
        &Syntax {
            flags: &[],
            valued: &["--out", "-o", "--scene", "--size", "--speed", "--preset", "--encoding", "--lasers"],
            group: None,
        },
    )?;
    if !a.positional.is_empty() {
        return Err(usage(format!("demo takes no positional arguments, got {:?}", a.positional)));
    }
    let out = PathBuf::from(a.get("--out").or(a.get("-o")).unwrap_or("xsurf-demo"));
    let scene = a.get("--scene").unwrap_or("pyramid");
    let s = scanner(&a, scene)?;
    let bag = out.join("bag");
    if bag.exists() {
        std::fs::remove_dir_all(&bag).with_context(|| format!("cannot clear {}", bag.display()))?;
    }
    let recon = out.join("reconstruction");
    if recon.exists() {
        std::fs::remove_dir_all(&recon).with_context(|| format!("cannot clear {}", recon.display()))?;
    }
    println!("1/3 synthesizing a {} scan ({} frames, 2 cameras) into {}", scene, s.frame_count(), bag.display());
    let summary = synth::write_bag(&bag, &s, true, 1, None, progress_printer("synth"))?;
    println!("2/3 reconstructing into {}", recon.display());
    let r = offline::reconstruct(&offline::Options {
        bag: bag.clone(),
        params_file: Some(bag.join("params.yaml")),
        out: recon.clone(),
        progress: true,
        xray: Some(bag.join(synth::XRAY_FILE)),
        ..Default::default()
    })?;
    print_report(&r, &recon.display().to_string());
    println!("3/3 accuracy against the synthetic scanner's ground truth:");
    let merged =
        xsurf_formats::ply::read(&mut std::io::BufReader::new(std::fs::File::open(recon.join("merged.ply"))?))?;
    let acc = eval::accuracy(eval::surface_errors(&s.scene, &merged.positions));
    let mut truth = Vec::new();
    for c in &summary.cameras {
        let t = xsurf_formats::ply::read(&mut std::io::BufReader::new(std::fs::File::open(
            bag.join(format!("truth_{c}.ply")),
        )?))?;
        truth.extend(t.positions.iter().map(|p| xsurf_core::geom::Vec3::new(p[0].into(), p[1].into(), p[2].into())));
    }
    let cov = eval::coverage(&truth, &merged.positions, 0.003);
    println!(
        "  {} points: RMS error {:.3} mm, 99th percentile {:.3} mm, max {:.3} mm, {:.3} % beyond 2 mm; coverage {:.1} % of what the cameras observe",
        acc.points,
        acc.rms_m * 1e3,
        acc.p99_m * 1e3,
        acc.max_m * 1e3,
        acc.outlier_fraction_2mm * 100.0,
        cov * 100.0
    );
    if let Some(e) = eval::pyramid_extents(&s.scene, &merged.positions) {
        println!(
            "  pyramid measured: base {:.2} x {:.2} mm, height {:.2} mm (true 210 x 297, 86 mm)",
            e.base_x_m * 1e3,
            e.base_y_m * 1e3,
            e.height_m * 1e3
        );
    }
    let acc_json = serde_json::json!({"rms_m": acc.rms_m, "p99_m": acc.p99_m, "max_m": acc.max_m, "outlier_fraction_2mm": acc.outlier_fraction_2mm, "coverage": cov, "points": acc.points});
    xsurf_formats::write_bytes_atomic(&out.join("accuracy.json"), serde_json::to_string_pretty(&acc_json)?.as_bytes())?;
    println!(
        "open {} (VRML) or {} (glTF) to look at the surface over the radiograph",
        recon.join("scene.wrl").display(),
        recon.join("scene.glb").display()
    );
    Ok(())
}

fn cmd_bag(args: &[String]) -> anyhow::Result<()> {
    match args.first().map(String::as_str) {
        Some("record") => bag_record(args),
        Some("play") => bag_play(args),
        Some("info") => bag_info(args),
        Some("reindex") => bag_reindex(args),
        Some(other) => Err(usage(format!("unknown bag command {other:?} (info, play, record, reindex)"))),
        None => Err(usage("bag needs a command (info, play, record, reindex)")),
    }
}

/// `xsurf bag record -o DIR [TOPIC... | --all] [--zstd] [--split-by-scan] [--duration S]`.
fn bag_record(args: &[String]) -> anyhow::Result<()> {
    // Started as a launch file's node, it is given `--ros-args ...` (its name and
    // namespace): a recorder has no use for them.
    let end = args.iter().position(|a| a == "--ros-args").unwrap_or(args.len());
    let args = &args[..end];
    let a = Args::parse(
        &args[1..],
        &Syntax {
            flags: &["--all", "--zstd", "--split-by-scan"],
            valued: &["-o", "--output", "--duration"],
            group: None,
        },
    )?;
    let out = a.get("-o").or(a.get("--output")).ok_or_else(|| usage("bag record needs -o DIR"))?;
    let opts = crate::record::RecordOptions {
        topics: a.positional.clone(),
        all: a.has("--all"),
        zstd: a.has("--zstd"),
        split_by_scan: a.has("--split-by-scan"),
        duration_s: a
            .get("--duration")
            .map(|d| d.parse())
            .transpose()
            .map_err(|_| usage("--duration: not a number"))?,
    };
    let n = crate::record::record(Path::new(out), &opts)?;
    eprintln!("bag record: {n} messages written to {out}");
    Ok(())
}

/// `xsurf bag play DIR [--rate R] [--loop] [--clock] [--topics T1,T2] [--start-offset S] [--delay S]`.
fn bag_play(args: &[String]) -> anyhow::Result<()> {
    let a = Args::parse(
        &args[1..],
        &Syntax {
            flags: &["--loop", "--clock"],
            valued: &["--rate", "--start-offset", "--delay", "--topics"],
            group: None,
        },
    )?;
    let [dir] = a.positional.as_slice() else { return Err(usage("bag play needs one DIR")) };
    let opts = crate::play::PlayOptions {
        rate: a.num("--rate", 1.0)?,
        repeat: a.has("--loop"),
        clock: a.has("--clock"),
        topics: a.get("--topics").map(|t| t.split(',').map(str::to_string).collect()).unwrap_or_default(),
        start_offset_s: a.num("--start-offset", 0.0)?,
        delay_s: a.num("--delay", 1.0)?,
    };
    let n = crate::play::play(Path::new(dir), &opts)?;
    eprintln!("bag play: {n} messages published");
    Ok(())
}

/// `xsurf bag info DIR`.
fn bag_info(args: &[String]) -> anyhow::Result<()> {
    let [dir] = &args[1..] else { return Err(usage("bag info needs one DIR")) };
    let bag = xsurf_formats::bag::Bag::open(Path::new(dir))?;
    match &bag.indexed {
        // A recorder killed before it wrote metadata.yaml: what its files hold.
        Some(cut) => {
            eprintln!(
                "bag info: {dir} has no metadata.yaml; indexed from its storage files (`xsurf bag reindex {dir}` writes one)"
            );
            for c in cut {
                eprintln!("bag info: {c}; counted up to there");
            }
        }
        None => bag.verify_storage()?,
    }
    write_stdout(&bag.info());
    Ok(())
}

/// `xsurf bag reindex DIR [--force]`.
fn bag_reindex(args: &[String]) -> anyhow::Result<()> {
    let a = Args::parse(&args[1..], &Syntax { flags: &["--force"], valued: &[], group: None })?;
    let [dir] = a.positional.as_slice() else { return Err(usage("bag reindex needs one DIR")) };
    let r = xsurf_formats::bag::reindex(Path::new(dir), a.has("--force"))?;
    for c in &r.cut {
        eprintln!("bag reindex: {c}; its messages before that are indexed");
    }
    println!(
        "bag reindex: {}/metadata.yaml written: {} file(s), {} topic(s), {} messages",
        dir,
        r.metadata.files.len(),
        r.metadata.topics.len(),
        r.metadata.message_count
    );
    Ok(())
}

fn cmd_launch(args: &[String]) -> ExitCode {
    let mut file = None;
    let mut composed = false;
    let mut cli = std::collections::BTreeMap::new();
    for a in args {
        if a == "--composed" {
            composed = true;
        } else if let Some((k, v)) = a.split_once(":=") {
            cli.insert(k.to_string(), v.to_string());
        } else if file.is_none() && !a.starts_with('-') {
            file = Some(PathBuf::from(a));
        } else {
            eprintln!("xsurf launch: unexpected argument {a:?}\n{}", command_usage(&["launch".to_string()]));
            return ExitCode::from(2);
        }
    }
    let Some(file) = file else {
        eprintln!("xsurf launch: name a launch file\n{}", command_usage(&["launch".to_string()]));
        return ExitCode::from(2);
    };
    let nodes = match crate::launch::load(&file, &cli) {
        Ok(n) => n,
        Err(e) => {
            eprintln!("xsurf launch: error: {e:#}");
            return ExitCode::from(2);
        }
    };
    match crate::launch::run(&nodes, composed) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("xsurf launch: error: {e:#}");
            ExitCode::from(1)
        }
    }
}

/// Runs `xsurf` with this process's arguments.
pub fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().is_some_and(|a| a == "--version" || a == "-V") {
        println!("xsurf {}", env!("CARGO_PKG_VERSION"));
        return ExitCode::SUCCESS;
    }
    // `xsurf compose --help`: how to compose, and the node types; `xsurf compose NODE_TYPE --help`
    // (or `/NS/NODE_TYPE`, `/NS/NAME=NODE_TYPE`): that node type's topics and parameters, as its
    // executable's --help prints them (a node type without an executable has no other).
    if args.first().is_some_and(|a| a == "compose") && args.iter().skip(1).any(|a| a == "--help" || a == "-h") {
        let named: Vec<&str> = args[1..]
            .iter()
            .filter_map(|a| {
                let ty = a.rsplit_once('=').map_or(a.as_str(), |(_, t)| t);
                let ty = ty.rsplit('/').next().unwrap_or(ty);
                crate::registry::NODE_NAMES.iter().copied().find(|n| *n == ty)
            })
            .collect();
        if !named.is_empty() {
            let help: Vec<String> = named.iter().map(|n| crate::host::node_help(n)).collect();
            write_stdout(&help.join("\n"));
            return ExitCode::SUCCESS;
        }
        println!(
            "usage: xsurf compose /NS/NODE_TYPE... | /NS/NAME=NODE_TYPE... [--ros-args ...]\n  run several nodes in one process, connected in memory, every topic still on DDS\n  node types: {}\n  example: xsurf compose /cam1/edge_detector /cam1/triangulator --ros-args --params-file params.yaml\n  each node's topics and parameters: xsurf compose NODE_TYPE --help (or its executable's --help)",
            crate::registry::NODE_NAMES.join(", ")
        );
        return ExitCode::SUCCESS;
    }
    // `xsurf CMD --help` (or -h) anywhere: the usage, exit 0.
    if args.iter().any(|a| a == "--help" || a == "-h") && args.first().map(String::as_str) != Some("compose") {
        write_stdout(&format!("{}\n", command_usage(&args)));
        return ExitCode::SUCCESS;
    }
    if args.first().map(String::as_str) == Some("compose") {
        // Logging levels come from its own ROS arguments.
        return crate::host::compose(&args[1..]);
    }
    if args.first().map(String::as_str) == Some("launch") {
        return cmd_launch(&args[1..]);
    }
    xsurf_runtime::logging::init(log::LevelFilter::Info, vec![]);
    let r = match args.first().map(String::as_str) {
        Some("demo") => cmd_demo(&args[1..]),
        Some("synth") => cmd_synth(&args[1..]),
        Some("reconstruct") => cmd_reconstruct(&args[1..]),
        Some("bag") => cmd_bag(&args[1..]),
        Some("pacs") => cmd_pacs(&args[1..]),
        Some("param") => crate::param_client::run(&args[1..]),
        Some("calibrate") => calibrate::run(&args[1..]),
        Some("-h" | "--help" | "help") => {
            write_stdout(&format!("{USAGE}\n"));
            Ok(())
        }
        Some(other) => Err(usage(format!("unknown command {other:?}"))),
        None => Err(usage("no command given")),
    };
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xsurf: error: {e:#}");
            if e.downcast_ref::<UsageError>().is_some() {
                eprintln!("{}", command_usage(&args));
                ExitCode::from(2)
            } else if e.downcast_ref::<xsurf_runtime::params::ParamError>().is_some() {
                // A refused parameter (a params file's bad value): as a node executable, exit 2.
                ExitCode::from(2)
            } else if e.downcast_ref::<Incomplete>().is_some() {
                ExitCode::from(3)
            } else {
                ExitCode::from(1)
            }
        }
    }
}
