//! The scan in the hospital's archive (issue 21), against a real PACS: Orthanc (Debian's
//! package), started here unprivileged on loopback ports with a temporary storage, stopped by
//! its PID. dcmtk's findscu and getscu find and fetch what we stored; pydicom and trimesh read
//! it back; dciodvfy checks the radiograph, and the Surface Mesh module (the Surface Scan IODs
//! are unknown to it: the surface is checked labelled as a Surface Segmentation, which shares
//! that module).
#![allow(clippy::unwrap_used, clippy::too_many_lines)]

mod common;
use common::*;
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::{Duration, Instant};

/// An Orthanc server of the test's own.
struct Orthanc {
    child: Option<Child>,
    dir: PathBuf,
    dicom_port: u16,
    http_port: u16,
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

impl Orthanc {
    /// Orthanc in `dir` (its storage kept there), or `None` where it is not installed (unless
    /// CI requires the checkers).
    fn start(dir: &Path) -> Option<Orthanc> {
        if Command::new("Orthanc").arg("--version").output().is_err() {
            assert!(
                std::env::var_os("XSURF_REQUIRE_CHECKERS").is_none(),
                "Orthanc is needed: bash scripts/setup-venv.sh"
            );
            eprintln!("skipped: no Orthanc");
            return None;
        }
        std::fs::create_dir_all(dir).unwrap();
        let mut o = Orthanc { child: None, dir: dir.to_path_buf(), dicom_port: free_port(), http_port: free_port() };
        o.run();
        Some(o)
    }

    /// Starts it (again), on the same ports and storage.
    fn run(&mut self) {
        let db = self.dir.join("db");
        let config = serde_json::json!({
            "Name": "xsurf-test",
            "StorageDirectory": db,
            "IndexDirectory": db,
            "HttpPort": self.http_port,
            "RemoteAccessAllowed": false,
            "AuthenticationEnabled": false,
            "DicomServerEnabled": true,
            "DicomAet": "ORTHANC",
            "DicomPort": self.dicom_port,
            "DicomCheckCalledAet": true,
            "UnknownSopClassAccepted": false,
            "DicomAlwaysAllowEcho": true,
            "DicomAlwaysAllowStore": true,
            "DicomAlwaysAllowFind": true,
            "DicomAlwaysAllowGet": true,
            "Plugins": [],
        });
        let cfg = self.dir.join("orthanc.json");
        std::fs::write(&cfg, serde_json::to_string_pretty(&config).unwrap()).unwrap();
        let log = std::fs::File::create(self.dir.join("orthanc.log")).unwrap();
        let child = Command::new("Orthanc").arg(&cfg).stdout(log.try_clone().unwrap()).stderr(log).spawn().unwrap();
        self.child = Some(child);
        let t0 = Instant::now();
        while self.http("/system").is_none() {
            assert!(t0.elapsed() < Duration::from_secs(60), "Orthanc did not start: {}", self.log());
            std::thread::sleep(Duration::from_millis(200));
        }
        // The DICOM port too.
        while std::net::TcpStream::connect(("127.0.0.1", self.dicom_port)).is_err() {
            assert!(t0.elapsed() < Duration::from_secs(60), "Orthanc's DICOM port is not open: {}", self.log());
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    fn log(&self) -> String {
        std::fs::read_to_string(self.dir.join("orthanc.log")).unwrap_or_default()
    }

    /// Stops it by its PID (SIGTERM), waiting for it to end.
    fn stop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = Command::new("kill").arg("-TERM").arg(c.id().to_string()).status();
            let t0 = Instant::now();
            while c.try_wait().unwrap().is_none() {
                if t0.elapsed() > Duration::from_secs(20) {
                    let _ = c.kill();
                }
                std::thread::sleep(Duration::from_millis(50));
            }
        }
    }

    fn addr(&self) -> String {
        format!("ORTHANC@127.0.0.1:{}", self.dicom_port)
    }

    /// A REST GET's body, or `None` when it does not answer.
    fn http(&self, path: &str) -> Option<String> {
        use std::io::{Read, Write};
        let mut s = std::net::TcpStream::connect(("127.0.0.1", self.http_port)).ok()?;
        s.set_read_timeout(Some(Duration::from_secs(10))).ok()?;
        write!(s, "GET {path} HTTP/1.0\r\nHost: localhost\r\n\r\n").ok()?;
        let mut body = Vec::new();
        s.read_to_end(&mut body).ok()?;
        let text = String::from_utf8_lossy(&body).into_owned();
        let (head, body) = text.split_once("\r\n\r\n")?;
        head.starts_with("HTTP/1.").then_some(())?;
        head.contains(" 200 ").then(|| body.to_string())
    }

    fn json(&self, path: &str) -> serde_json::Value {
        serde_json::from_str(&self.http(path).unwrap_or_else(|| panic!("GET {path}: {}", self.log()))).unwrap()
    }

    /// Instances stored.
    fn instances(&self) -> usize {
        self.json("/instances").as_array().unwrap().len()
    }
}

impl Drop for Orthanc {
    fn drop(&mut self) {
        self.stop();
    }
}

/// dciodvfy's errors on `file` (its lines starting "Error").
fn dciodvfy_errors(file: &Path) -> Vec<String> {
    let out = Command::new("dciodvfy").arg(file).output().unwrap();
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    text.lines().filter(|l| l.starts_with("Error")).map(str::to_string).collect()
}

/// dcmtk's `tool` (findscu, getscu) as XSURF to the test's Orthanc, with the query `keys`, its
/// files into `out`.
fn dcmtk_query(tool: &str, port: u16, keys: &[&str], out: &Path, extra: &[&str]) {
    let port = port.to_string();
    let mut args: Vec<&str> = vec!["-S", "-aet", "XSURF", "-aec", "ORTHANC", "127.0.0.1", &port];
    for k in keys {
        args.extend(["-k", k]);
    }
    args.extend(extra);
    args.extend(["-od", out.to_str().unwrap()]);
    let r = Command::new(tool).args(&args).output().unwrap();
    assert!(r.status.success(), "{tool} {args:?}: {}", String::from_utf8_lossy(&r.stderr));
}

/// A pyramid bag of the test's own, with a fresh radiograph (today's DX writer).
fn bag(dir: &Path) -> PathBuf {
    let b = dir.join("bag");
    copy_bag(pyramid_bag(), &b);
    b
}

#[test]
fn a_reconstructed_scan_lands_in_orthanc_as_one_study_with_the_radiograph() {
    let Some(py) = python() else { return };
    let dir = scratch("pacs-study");
    let Some(orthanc) = Orthanc::start(&dir.join("orthanc")) else { return };
    let bag = bag(&dir);
    // The radiograph we write is a valid DX (dciodvfy knows that IOD).
    assert_eq!(dciodvfy_errors(&bag.join("xray.dcm")), Vec::<String>::new());
    let out = dir.join("out");
    let x = bag.join("xray.dcm");
    // The points with their colours too (a Surface Scan Point Cloud in the same series).
    let params = dir.join("params.yaml");
    let text = std::fs::read_to_string(bag.join("params.yaml")).unwrap();
    std::fs::write(&params, format!("{text}\n/merger:\n  ros__parameters:\n    point_cloud_dcm: true\n")).unwrap();
    let r = xsurf(&[
        "reconstruct",
        bag.to_str().unwrap(),
        "--params-file",
        params.to_str().unwrap(),
        "--xray",
        x.to_str().unwrap(),
        "--pacs",
        &orthanc.addr(),
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(r.status.success(), "{}\n{}", String::from_utf8_lossy(&r.stderr), String::from_utf8_lossy(&r.stdout));
    assert!(String::from_utf8_lossy(&r.stdout).contains("stored in"), "{}", String::from_utf8_lossy(&r.stdout));
    // Nothing left waiting.
    assert_eq!(
        std::fs::read_dir(out.join("pacs_queue"))
            .unwrap()
            .filter(|e| !e.as_ref().unwrap().file_name().to_string_lossy().starts_with('.'))
            .count(),
        0
    );
    // The radiograph in the scan's frame is still a valid DX, and the surface's Surface Mesh
    // module is valid: labelled as a Surface Segmentation, dciodvfy finds only what that IOD
    // has beyond ours (its segment and content identification, and the Laterality it asks of
    // any image series).
    assert_eq!(dciodvfy_errors(&out.join("xray.dcm")), Vec::<String>::new());
    let seg = dir.join("as-segmentation.dcm");
    checker("check_surface_dcm.py", &[Path::new("relabel"), &out.join("surface.dcm"), &seg]).unwrap();
    let expected = ["<Laterality>", "<ContentLabel>", "<ContentDescription>", "<SegmentSequence>"];
    let unexpected: Vec<String> =
        dciodvfy_errors(&seg).into_iter().filter(|e| !expected.iter().any(|x| e.contains(x))).collect();
    assert_eq!(unexpected, Vec::<String>::new());

    // One study, found by findscu: two series, DX and OSS.
    let ours = checker(
        "check_surface_dcm.py",
        &[Path::new("compare"), &out.join("surface.dcm"), &out.join("merged.ply"), &out.join("xray.dcm")],
    )
    .unwrap();
    let study = ours["study_uid"].as_str().unwrap().to_string();
    assert_eq!(ours["xray_study_uid"], ours["study_uid"]);
    assert_eq!(ours["xray_frame_uid"], ours["frame_uid"]);
    assert_eq!(ours["patient_id"], "XSURF-SYNTH");
    let found = dir.join("found");
    std::fs::create_dir_all(&found).unwrap();
    let s_key = format!("StudyInstanceUID={study}");
    let keys = ["QueryRetrieveLevel=SERIES", &s_key, "SeriesInstanceUID", "Modality"];
    dcmtk_query("findscu", orthanc.dicom_port, &keys, &found, &["-X"]);
    let series = checker("check_surface_dcm.py", &[Path::new("series"), &found]).unwrap();
    let mut modalities: Vec<&str> =
        series["series"].as_array().unwrap().iter().map(|s| s["modality"].as_str().unwrap()).collect();
    modalities.sort();
    assert_eq!(modalities, ["DX", "OSS"], "{series}");
    assert_eq!(orthanc.json("/studies").as_array().unwrap().len(), 1);

    // Fetched back by getscu: the surface as merged.ply has it, to float precision.
    let fetched = dir.join("fetched");
    std::fs::create_dir_all(&fetched).unwrap();
    dcmtk_query("getscu", orthanc.dicom_port, &["QueryRetrieveLevel=STUDY", &s_key], &fetched, &[]);
    let files: Vec<PathBuf> = std::fs::read_dir(&fetched).unwrap().map(|e| e.unwrap().path()).collect();
    assert_eq!(files.len(), 3, "{files:?}");
    let cloud = files.iter().find(|f| f.file_name().unwrap().to_string_lossy().starts_with("SSp")).unwrap();
    let c = checker("check_surface_dcm.py", &[Path::new("cloud"), cloud, &out.join("merged.ply")]).unwrap();
    assert_eq!(c["points"], c["ply_points"], "{c}");
    assert_eq!(c["colours"], c["ply_points"], "{c}");
    assert!(c["max_coordinate_difference_m"].as_f64().unwrap() <= 1e-6, "{c}");
    assert_eq!(c["series_uid"], ours["series_uid"], "one OSS series");
    let local =
        checker("check_surface_dcm.py", &[Path::new("cloud"), &out.join("points.dcm"), &out.join("merged.ply")])
            .unwrap();
    assert_eq!(c["lab_md5"], local["lab_md5"], "the colours as written");
    let surface = files.iter().find(|f| f.file_name().unwrap().to_string_lossy().starts_with("SSm")).unwrap();
    let xray = files.iter().find(|f| f.file_name().unwrap().to_string_lossy().starts_with("DX")).unwrap();
    let back =
        checker("check_surface_dcm.py", &[Path::new("compare"), surface, &out.join("merged.ply"), xray]).unwrap();
    assert_eq!(back["sop_class"], "1.2.840.10008.5.1.4.1.1.68.1");
    assert_eq!(back["modality"], "OSS");
    assert_eq!(back["points"], back["ply_points"]);
    assert_eq!(back["coordinates"], back["ply_points"]);
    assert_eq!(back["triangles"], back["ply_triangles"]);
    assert!(back["ply_points"].as_u64().unwrap() > 5000, "{back}");
    assert_eq!(back["triangles_equal"], true);
    assert_eq!((back["index_min"].as_u64(), back["index_max"].as_u64()), (Some(1), back["ply_points"].as_u64()));
    // float32 millimetres against float32 metres: within a few units of the last place.
    let diff = back["max_coordinate_difference_m"].as_f64().unwrap();
    let scale = back["max_coordinate_m"].as_f64().unwrap();
    assert!(diff <= scale * 4.0 * f64::from(f32::EPSILON), "{diff} m at {scale} m");
    assert_eq!(back["acquisition_type"], serde_json::json!(["114203", "DCM", "Laser scanning"]));
    for k in ["study_uid", "frame_uid", "patient_id", "xray_frame_uid", "xray_study_uid"] {
        assert_eq!(back[k], ours[k], "{k}");
    }
    assert_eq!(back["xray_frame_uid"], back["frame_uid"]);
    assert!(back["xray_pixels"].as_u64().unwrap() > 1000);
    let _ = py;
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_pacs_that_is_down_or_wrong_gets_the_scan_later_and_once() {
    let Some(_py) = python() else { return };
    let dir = scratch("pacs-down");
    let Some(mut orthanc) = Orthanc::start(&dir.join("orthanc")) else { return };
    let bag = bag(&dir);
    let x = bag.join("xray.dcm");
    let reconstruct = |out: &Path, addr: &str| {
        xsurf(&[
            "reconstruct",
            bag.to_str().unwrap(),
            "--xray",
            x.to_str().unwrap(),
            "--pacs",
            addr,
            "--out",
            out.to_str().unwrap(),
            "--quiet",
        ])
    };
    // A wrong AE title: refused, named, and the scan queued.
    let out = dir.join("out");
    let wrong = format!("NOT_ORTHANC@127.0.0.1:{}", orthanc.dicom_port);
    let r = reconstruct(&out, &wrong);
    assert_clean_failure(&r, 1, "called AE title not recognized");
    assert_clean_failure(&r, 1, &wrong);
    assert_clean_failure(&r, 1, "pacs_queue");
    let queue = out.join("pacs_queue");
    let waiting = |q: &Path| {
        std::fs::read_dir(q)
            .unwrap()
            .filter(|e| !e.as_ref().unwrap().file_name().to_string_lossy().starts_with('.'))
            .count()
    };
    assert_eq!(waiting(&queue), 1);
    // A wrong port: nobody there, named.
    let r = xsurf(&["pacs", "send", queue.to_str().unwrap(), &format!("ORTHANC@127.0.0.1:{}", free_port())]);
    assert_clean_failure(&r, 1, "could not connect");
    assert_eq!(waiting(&queue), 1);
    // The PACS down during the scan: the scan waits.
    orthanc.stop();
    let out2 = dir.join("out2");
    let r = reconstruct(&out2, &orthanc.addr());
    assert_clean_failure(&r, 1, &orthanc.addr());
    assert_eq!(waiting(&out2.join("pacs_queue")), 1);
    // A node that keeps the queue: its sender tries, backs off, and sends once the PACS is back.
    let client = xsurf_nodes::pacs::Client { calling: "XSURF".into(), timeout: Duration::from_secs(5) };
    let peer: xsurf_nodes::pacs::Peer = orthanc.addr().parse().unwrap();
    let q = xsurf_nodes::pacs::Queue::open(&out2.join("pacs_queue")).unwrap();
    let sender = xsurf_nodes::pacs::Sender::spawn(q.clone(), client.clone(), peer.clone());
    let t0 = Instant::now();
    while sender.counts().failures.load(std::sync::atomic::Ordering::Relaxed) < 2 {
        assert!(t0.elapsed() < Duration::from_secs(30), "the sender does not retry");
        std::thread::sleep(Duration::from_millis(100));
    }
    // A restart of the node: the queue is on disk, and the next sender takes it.
    drop(sender);
    assert_eq!(q.entries().len(), 1);
    orthanc.run();
    assert_eq!(orthanc.instances(), 0);
    let sender = xsurf_nodes::pacs::Sender::spawn(q.clone(), client, peer);
    let t0 = Instant::now();
    while !q.entries().is_empty() {
        assert!(t0.elapsed() < Duration::from_secs(60), "the queued scan was not sent: {}", orthanc.log());
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_eq!(sender.counts().sent.load(std::sync::atomic::Ordering::Relaxed), 1);
    drop(sender);
    assert_eq!(orthanc.instances(), 2, "surface and radiograph, once");
    // The first scan, queued by the wrong AE title, by hand: the same scan (the same UIDs), so
    // the PACS still holds it once.
    let r = xsurf(&["pacs", "send", queue.to_str().unwrap(), &orthanc.addr()]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert_eq!(waiting(&queue), 0);
    assert_eq!(orthanc.instances(), 2);
    let r = xsurf(&["pacs", "echo", &orthanc.addr()]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    // A SOP class the PACS does not take: refused, naming the PACS and the class.
    let odd = dir.join("odd.dcm");
    let class = "1.2.826.0.1.3680043.8.498.424242";
    checker("check_surface_dcm.py", &[Path::new("relabel"), &out2.join("surface.dcm"), &odd, Path::new(class)])
        .unwrap();
    let r = xsurf(&["pacs", "send", odd.to_str().unwrap(), &orthanc.addr()]);
    assert_clean_failure(&r, 1, class);
    assert_clean_failure(&r, 1, &orthanc.addr());
    assert_eq!(orthanc.instances(), 2);
    std::fs::remove_dir_all(&dir).unwrap();
}
