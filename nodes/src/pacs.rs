//! Sending scans to the hospital's PACS: DICOM C-ECHO and C-STORE (PS3.7 9.1.5, 9.1.1) over
//! dicom-rs's upper layer, and a queue on disk so that nothing is lost while the PACS is down.
//!
//! - A PACS is named `AET@host:port` ([`Peer`]); we are the calling AE title of
//!   [`Client::calling`].
//! - [`store`] proposes, for each SOP class among the files, the file's own transfer syntax
//!   and the two uncompressed little-endian ones; a file goes in its own syntax when the PACS
//!   accepts it, else re-encoded in an accepted uncompressed one. An association refused, a SOP
//!   class not accepted, or a failure status is an error naming the PACS, the SOP class and the
//!   status code.
//! - [`Queue`] keeps each scan's files in a folder of their own under the queue's folder,
//!   written whole before they appear (copied to a hidden name, then renamed), removed only
//!   once the PACS has stored every file. [`Sender`] drains it on a thread of its own, oldest
//!   first, retrying with a backoff (1 s doubling to 60 s) while the PACS does not answer; a
//!   queue left by a node that stopped is sent when the next one starts.

use anyhow::Context;
use dicom_core::value::PrimitiveValue;
use dicom_core::{DataElement, VR};
use dicom_dictionary_std::tags;
use dicom_encoding::TransferSyntaxIndex;
use dicom_object::{InMemDicomObject, OpenFileOptions};
use dicom_transfer_syntax_registry::TransferSyntaxRegistry;
use dicom_ul::pdu::{PDataValue, PDataValueType, PresentationContextResultReason};
use dicom_ul::{ClientAssociation, ClientAssociationOptions, Pdu};
use std::io::Write;
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc;
use std::sync::Arc;
use std::time::Duration;

/// Verification SOP Class (C-ECHO).
const VERIFICATION: &str = "1.2.840.10008.1.1";
/// Explicit VR Little Endian.
const EXPLICIT_VR_LE: &str = "1.2.840.10008.1.2.1";
/// Implicit VR Little Endian.
const IMPLICIT_VR_LE: &str = "1.2.840.10008.1.2";

/// A PACS: its AE title, host and port.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Peer {
    /// The called AE title.
    pub ae_title: String,
    /// Host name or address.
    pub host: String,
    /// TCP port.
    pub port: u16,
}

/// Checks an AE title (PS3.5 6.2, VR AE): 1 to 16 characters of the default repertoire, no
/// backslash or control character, not only spaces.
pub fn check_ae_title(t: &str) -> Result<(), String> {
    if t.trim().is_empty() {
        return Err("an AE title is 1 to 16 characters, not empty".into());
    }
    if t.len() > 16 {
        return Err(format!("AE title {t:?} has {} characters, at most 16", t.len()));
    }
    if let Some(c) = t.chars().find(|c| !c.is_ascii() || c.is_ascii_control() || *c == '\\') {
        return Err(format!("AE title {t:?} holds {c:?}: ASCII letters, digits, spaces and punctuation but \\"));
    }
    Ok(())
}

impl std::str::FromStr for Peer {
    type Err = String;

    /// Parses `AET@host:port`.
    fn from_str(s: &str) -> Result<Peer, String> {
        let (aet, addr) = s.split_once('@').ok_or_else(|| format!("{s:?}: expected AET@host:port"))?;
        check_ae_title(aet).map_err(|e| format!("{s:?}: {e}"))?;
        let (host, port) = addr.rsplit_once(':').ok_or_else(|| format!("{s:?}: expected AET@host:port (no port)"))?;
        if host.is_empty() {
            return Err(format!("{s:?}: expected AET@host:port (no host)"));
        }
        let port: u16 =
            port.parse().ok().filter(|&p| p > 0).ok_or_else(|| format!("{s:?}: port {port:?} is not 1..65535"))?;
        Ok(Peer { ae_title: aet.to_string(), host: host.trim_matches(['[', ']']).to_string(), port })
    }
}

impl std::fmt::Display for Peer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.host.contains(':') {
            write!(f, "{}@[{}]:{}", self.ae_title, self.host, self.port)
        } else {
            write!(f, "{}@{}:{}", self.ae_title, self.host, self.port)
        }
    }
}

/// What failed in talking to a PACS; each names the PACS.
#[derive(Debug, thiserror::Error)]
pub enum PacsError {
    /// No association: the PACS did not answer, refused it, or accepted none of our contexts.
    #[error("PACS {peer}: {what}")]
    Association {
        /// The PACS.
        peer: String,
        /// What happened.
        what: String,
    },
    /// The PACS answered a C-STORE or C-ECHO with a failure status.
    #[error("PACS {peer}: {operation} of {file} ({sop_class}) failed: status {status:04X}H ({meaning})")]
    Status {
        /// The PACS.
        peer: String,
        /// C-STORE or C-ECHO.
        operation: &'static str,
        /// The file sent.
        file: String,
        /// Its SOP class, by name and UID.
        sop_class: String,
        /// The status code.
        status: u16,
        /// What the code means (PS3.7 C, PS3.4 B.2.3).
        meaning: &'static str,
    },
    /// A file that cannot be read or sent.
    #[error("{file}: {what}")]
    File {
        /// The file.
        file: String,
        /// What is wrong.
        what: String,
    },
}

/// The meaning of a DIMSE status code (PS3.7 Annex C, the Storage Service Class PS3.4 B.2.3).
pub fn status_meaning(status: u16) -> &'static str {
    match status {
        0x0000 => "success",
        0x0001 | 0x0107 | 0x0116 | 0xB000..=0xBFFF => "warning",
        0x0110 => "processing failure",
        0x0111 => "duplicate SOP instance",
        0x0117 => "invalid object instance",
        0x0118 => "no such SOP class",
        0x0119 => "class-instance conflict",
        0x0122 => "refused: SOP class not supported",
        0x0124 => "refused: not authorized",
        0x0210 => "duplicate invocation",
        0x0211 => "unrecognized operation",
        0x0212 => "mistyped argument",
        0x0213 => "resource limitation",
        0xA700..=0xA7FF => "refused: out of resources",
        0xA900..=0xA9FF => "error: data set does not match SOP class",
        0xC000..=0xCFFF => "error: cannot understand",
        0xFE00 => "cancelled",
        _ => "failure",
    }
}

/// A SOP class by name (those we send) and UID.
fn class_name(uid: &str) -> String {
    use dicom_dictionary_std::uids;
    let name = match uid {
        uids::SURFACE_SCAN_MESH_STORAGE => "Surface Scan Mesh Storage",
        uids::SURFACE_SCAN_POINT_CLOUD_STORAGE => "Surface Scan Point Cloud Storage",
        uids::DIGITAL_X_RAY_IMAGE_STORAGE_FOR_PRESENTATION => "Digital X-Ray Image Storage - For Presentation",
        uids::DIGITAL_X_RAY_IMAGE_STORAGE_FOR_PROCESSING => "Digital X-Ray Image Storage - For Processing",
        uids::COMPUTED_RADIOGRAPHY_IMAGE_STORAGE => "Computed Radiography Image Storage",
        uids::SECONDARY_CAPTURE_IMAGE_STORAGE => "Secondary Capture Image Storage",
        VERIFICATION => "Verification",
        _ => return uid.to_string(),
    };
    format!("{name} {uid}")
}

/// Our side of an association.
#[derive(Debug, Clone)]
pub struct Client {
    /// The calling AE title (ours).
    pub calling: String,
    /// Connection, read and write timeout.
    pub timeout: Duration,
}

impl Client {
    /// A client with AE title `calling` and a 30 s timeout.
    pub fn new(calling: &str) -> Result<Client, String> {
        check_ae_title(calling)?;
        Ok(Client { calling: calling.to_string(), timeout: Duration::from_secs(30) })
    }

    fn associate(
        &self,
        peer: &Peer,
        contexts: &[(String, Vec<String>)],
    ) -> Result<ClientAssociation<TcpStream>, PacsError> {
        let mut o = ClientAssociationOptions::new()
            .calling_ae_title(self.calling.as_str())
            .called_ae_title(peer.ae_title.as_str())
            .connection_timeout(self.timeout)
            .read_timeout(self.timeout)
            .write_timeout(self.timeout);
        for (class, syntaxes) in contexts {
            o = o.with_presentation_context(class.as_str(), syntaxes.iter().map(String::as_str).collect());
        }
        let addr = format!("{}:{}", peer.host, peer.port);
        o.establish(addr.as_str()).map_err(|e| {
            let what = match &e {
                dicom_ul::association::Error::Rejected { association_rj, .. } => {
                    format!("association refused ({}), calling AE {:?}", association_rj.source, self.calling)
                }
                dicom_ul::association::Error::NoAcceptedPresentationContexts { .. } => format!(
                    "no presentation context accepted for {}",
                    contexts.iter().map(|(c, _)| class_name(c)).collect::<Vec<_>>().join(", ")
                ),
                other => format!("cannot associate: {}", error_chain(other)),
            };
            PacsError::Association { peer: peer.to_string(), what }
        })
    }
}

fn error_chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut src = e.source();
    while let Some(c) = src {
        s.push_str(": ");
        s.push_str(&c.to_string());
        src = c.source();
    }
    s
}

fn command(elements: Vec<DataElement<InMemDicomObject>>) -> Result<Vec<u8>, String> {
    // The command set is in Implicit VR Little Endian, its group length first (PS3.7 6.3.1).
    let body = InMemDicomObject::from_element_iter(elements);
    let ts = TransferSyntaxRegistry.get(IMPLICIT_VR_LE).ok_or("no implicit VR little endian")?;
    let mut bytes = Vec::new();
    body.write_dataset_with_ts(&mut bytes, ts).map_err(|e| e.to_string())?;
    let mut with_length = InMemDicomObject::new_empty();
    with_length.put(DataElement::new(tags::COMMAND_GROUP_LENGTH, VR::UL, PrimitiveValue::from(bytes.len() as u32)));
    let mut out = Vec::new();
    with_length.write_dataset_with_ts(&mut out, ts).map_err(|e| e.to_string())?;
    out.extend_from_slice(&bytes);
    Ok(out)
}

/// The status of the response on `scu`.
fn response_status(scu: &mut ClientAssociation<TcpStream>, peer: &Peer) -> Result<u16, PacsError> {
    let assoc = |what: String| PacsError::Association { peer: peer.to_string(), what };
    let pdu = scu.receive().map_err(|e| assoc(format!("no response: {}", error_chain(&e))))?;
    let Pdu::PData { data } = pdu else {
        return Err(assoc(format!("unexpected response {}", pdu.short_description())));
    };
    let v = data.first().ok_or_else(|| assoc("an empty response".into()))?;
    command_status(&v.data).map_err(|e| assoc(format!("malformed response: {e}")))
}

/// The Status (0000,0900) of a DIMSE response's command set (Implicit VR Little Endian, PS3.7
/// 6.3.1), read element by element with every length checked against the bytes (a PACS's
/// bytes are outside input: no length it claims is allocated).
pub fn command_status(b: &[u8]) -> Result<u16, String> {
    let mut pos = 0usize;
    while pos < b.len() {
        let head = b.get(pos..pos + 8).ok_or_else(|| format!("an element header cut short at byte offset {pos}"))?;
        let group = u16::from_le_bytes([head[0], head[1]]);
        let element = u16::from_le_bytes([head[2], head[3]]);
        let len = u32::from_le_bytes([head[4], head[5], head[6], head[7]]) as usize;
        if group != 0x0000 {
            return Err(format!("element ({group:04X},{element:04X}) at byte offset {pos} is not of the command set"));
        }
        let start = pos + 8;
        let value = b.get(start..start.saturating_add(len)).ok_or_else(|| {
            format!("element (0000,{element:04X}) at byte offset {pos} says {len} bytes; {} are left", b.len() - start)
        })?;
        if element == 0x0900 {
            return match value {
                [lo, hi] => Ok(u16::from_le_bytes([*lo, *hi])),
                _ => Err(format!("Status (0000,0900) at byte offset {pos} has {len} bytes, not 2")),
            };
        }
        pos = start + len;
    }
    Err("a response without a Status (0000,0900)".into())
}

/// C-ECHO to `peer`: `Ok` when it answers with success.
pub fn echo(client: &Client, peer: &Peer) -> Result<(), PacsError> {
    let mut scu =
        client.associate(peer, &[(VERIFICATION.into(), vec![EXPLICIT_VR_LE.into(), IMPLICIT_VR_LE.into()])])?;
    let pc = scu.presentation_contexts().first().map(|p| p.id).unwrap_or(1);
    let cmd = command(vec![
        DataElement::new(tags::AFFECTED_SOP_CLASS_UID, VR::UI, PrimitiveValue::from(VERIFICATION)),
        DataElement::new(tags::COMMAND_FIELD, VR::US, PrimitiveValue::from(0x0030u16)),
        DataElement::new(tags::MESSAGE_ID, VR::US, PrimitiveValue::from(1u16)),
        DataElement::new(tags::COMMAND_DATA_SET_TYPE, VR::US, PrimitiveValue::from(0x0101u16)),
    ])
    .map_err(|what| PacsError::Association { peer: peer.to_string(), what })?;
    scu.send(&Pdu::PData {
        data: vec![PDataValue {
            presentation_context_id: pc,
            value_type: PDataValueType::Command,
            is_last: true,
            data: cmd,
        }],
    })
    .map_err(|e| PacsError::Association {
        peer: peer.to_string(),
        what: format!("cannot send C-ECHO: {}", error_chain(&e)),
    })?;
    let status = response_status(&mut scu, peer)?;
    let _ = scu.release();
    if status != 0 {
        return Err(PacsError::Status {
            peer: peer.to_string(),
            operation: "C-ECHO",
            file: "-".into(),
            sop_class: class_name(VERIFICATION),
            status,
            meaning: status_meaning(status),
        });
    }
    Ok(())
}

/// A file stored in a PACS.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stored {
    /// The file.
    pub file: PathBuf,
    /// Its SOP class UID.
    pub sop_class: String,
    /// Its SOP instance UID.
    pub sop_instance: String,
    /// The status the PACS answered (0, or a warning).
    pub status: u16,
}

struct Outgoing {
    file: PathBuf,
    obj: dicom_object::DefaultDicomObject,
    class: String,
    instance: String,
    syntax: String,
}

fn trimmed(s: &str) -> String {
    s.trim_end_matches(['\0', ' ']).to_string()
}

/// The files to send, read: their SOP class, instance and transfer syntax.
fn outgoing(files: &[PathBuf]) -> Result<Vec<Outgoing>, PacsError> {
    files
        .iter()
        .map(|f| {
            let obj = OpenFileOptions::new().open_file(f).map_err(|e| PacsError::File {
                file: f.display().to_string(),
                what: format!("not a readable DICOM file: {e}"),
            })?;
            let meta = obj.meta();
            Ok(Outgoing {
                file: f.clone(),
                class: trimmed(&meta.media_storage_sop_class_uid),
                instance: trimmed(&meta.media_storage_sop_instance_uid),
                syntax: trimmed(meta.transfer_syntax()),
                obj,
            })
        })
        .collect()
}

/// The presentation contexts to propose, per SOP class and file syntax: one of the file's own
/// syntax alone (so that a PACS that takes it is not offered another: a file may not fit one,
/// as a point cloud's colours do not fit Explicit VR), then one of the uncompressed
/// little-endian syntaxes it is not in, for a PACS that does not take it.
fn contexts(out: &[Outgoing]) -> Vec<(String, Vec<String>)> {
    let mut contexts: Vec<(String, Vec<String>)> = Vec::new();
    for o in out {
        let fallback: Vec<String> =
            [EXPLICIT_VR_LE, IMPLICIT_VR_LE].into_iter().filter(|s| *s != o.syntax).map(String::from).collect();
        for ts in [vec![o.syntax.clone()], fallback] {
            if !contexts.iter().any(|(c, t)| *c == o.class && *t == ts) {
                contexts.push((o.class.clone(), ts));
            }
        }
    }
    contexts
}

/// C-STORE of every file in `files` to `peer` over one association, in order. The first
/// failure ends it (the files before it are stored).
pub fn store(client: &Client, peer: &Peer, files: &[PathBuf]) -> Result<Vec<Stored>, PacsError> {
    let out = outgoing(files)?;
    let contexts = contexts(&out);
    if contexts.is_empty() {
        return Ok(Vec::new());
    }
    let mut scu = client.associate(peer, &contexts)?;
    let accepted: Vec<_> = scu
        .presentation_contexts()
        .iter()
        .filter(|p| p.reason == PresentationContextResultReason::Acceptance)
        .cloned()
        .collect();
    let mut stored = Vec::new();
    for (n, o) in out.iter().enumerate() {
        match store_one(&mut scu, peer, &accepted, (n + 1) as u16, o) {
            Ok(s) => stored.push(s),
            Err(e) => {
                let _ = scu.abort();
                return Err(e);
            }
        }
    }
    let _ = scu.release();
    Ok(stored)
}

/// One C-STORE on `scu`, message `id`, in the accepted context that fits the file best.
fn store_one(
    scu: &mut ClientAssociation<TcpStream>,
    peer: &Peer,
    accepted: &[dicom_ul::pdu::PresentationContextNegotiated],
    id: u16,
    o: &Outgoing,
) -> Result<Stored, PacsError> {
    let assoc = |what: String| PacsError::Association { peer: peer.to_string(), what };
    let file_err = |what: String| PacsError::File { file: o.file.display().to_string(), what };
    let pc = accepted
        .iter()
        .filter(|p| trimmed(&p.abstract_syntax) == o.class)
        .max_by_key(|p| trimmed(&p.transfer_syntax) == o.syntax)
        .ok_or_else(|| {
            assoc(format!("{} not accepted (no presentation context) for {}", class_name(&o.class), o.file.display()))
        })?;
    let syntax = trimmed(&pc.transfer_syntax);
    let ts =
        TransferSyntaxRegistry.get(&syntax).ok_or_else(|| assoc(format!("transfer syntax {syntax} is unknown")))?;
    if syntax != o.syntax && ts.is_encapsulated_pixel_data() {
        return Err(file_err(format!("the PACS accepts {syntax} only, and the file is {}", o.syntax)));
    }
    let mut data = Vec::new();
    o.obj.write_dataset_with_ts(&mut data, ts).map_err(|e| file_err(format!("cannot encode in {syntax}: {e}")))?;
    let cmd = command(vec![
        DataElement::new(tags::AFFECTED_SOP_CLASS_UID, VR::UI, PrimitiveValue::from(o.class.as_str())),
        DataElement::new(tags::COMMAND_FIELD, VR::US, PrimitiveValue::from(0x0001u16)),
        DataElement::new(tags::MESSAGE_ID, VR::US, PrimitiveValue::from(id)),
        DataElement::new(tags::PRIORITY, VR::US, PrimitiveValue::from(0u16)),
        DataElement::new(tags::COMMAND_DATA_SET_TYPE, VR::US, PrimitiveValue::from(0x0000u16)),
        DataElement::new(tags::AFFECTED_SOP_INSTANCE_UID, VR::UI, PrimitiveValue::from(o.instance.as_str())),
    ])
    .map_err(assoc)?;
    let sent = |e: &dyn std::error::Error| assoc(format!("sending {} broke off: {}", o.file.display(), error_chain(e)));
    scu.send(&Pdu::PData {
        data: vec![PDataValue {
            presentation_context_id: pc.id,
            value_type: PDataValueType::Command,
            is_last: true,
            data: cmd,
        }],
    })
    .map_err(|e| sent(&e))?;
    let mut w = scu.send_pdata(pc.id);
    w.write_all(&data).map_err(|e| sent(&e))?;
    w.finish().map_err(|e| sent(&e))?;
    let status = response_status(scu, peer)?;
    if !matches!(status_meaning(status), "success" | "warning") {
        return Err(PacsError::Status {
            peer: peer.to_string(),
            operation: "C-STORE",
            file: o.file.display().to_string(),
            sop_class: class_name(&o.class),
            status,
            meaning: status_meaning(status),
        });
    }
    Ok(Stored { file: o.file.clone(), sop_class: o.class.clone(), sop_instance: o.instance.clone(), status })
}

/// The marker file of a queue's folder.
const QUEUE_MARK: &str = ".xsurf-pacs-queue";

/// A queue of scans to send, on disk: one folder per scan under its folder.
#[derive(Debug, Clone)]
pub struct Queue {
    dir: PathBuf,
}

impl Queue {
    /// The queue in `dir` (made if missing).
    pub fn open(dir: &Path) -> anyhow::Result<Queue> {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot make the PACS queue {}", dir.display()))?;
        let mark = dir.join(QUEUE_MARK);
        if !mark.exists() {
            std::fs::write(&mark, b"scans waiting for the PACS: one folder each, removed once stored\n")
                .with_context(|| format!("cannot write {}", mark.display()))?;
        }
        Ok(Queue { dir: dir.to_path_buf() })
    }

    /// Whether `dir` is a queue's folder.
    pub fn is_queue(dir: &Path) -> bool {
        dir.join(QUEUE_MARK).is_file()
    }

    /// The queue's folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Puts copies of `files` in the queue as entry `name`, replacing an entry of that name. The
    /// entry appears whole or not at all.
    pub fn enqueue(&self, name: &str, files: &[PathBuf]) -> anyhow::Result<PathBuf> {
        let tmp = self.dir.join(format!(".{name}.partial"));
        let _ = std::fs::remove_dir_all(&tmp);
        std::fs::create_dir_all(&tmp).with_context(|| format!("cannot make {}", tmp.display()))?;
        for f in files {
            let to = tmp.join(f.file_name().context("a file without a name")?);
            std::fs::copy(f, &to).with_context(|| format!("cannot copy {} into the PACS queue", f.display()))?;
            std::fs::File::open(&to)
                .and_then(|h| h.sync_all())
                .with_context(|| format!("cannot sync {}", to.display()))?;
        }
        let dst = self.dir.join(name);
        let _ = std::fs::remove_dir_all(&dst);
        std::fs::rename(&tmp, &dst).with_context(|| format!("cannot rename {} to {}", tmp.display(), dst.display()))?;
        std::fs::File::open(&self.dir).and_then(|d| d.sync_all()).ok();
        Ok(dst)
    }

    /// The entries waiting, oldest name first.
    pub fn entries(&self) -> Vec<PathBuf> {
        let mut v: Vec<PathBuf> = std::fs::read_dir(&self.dir)
            .map(|rd| {
                rd.filter_map(Result::ok)
                    .filter(|e| !e.file_name().to_string_lossy().starts_with('.') && e.path().is_dir())
                    .map(|e| e.path())
                    .collect()
            })
            .unwrap_or_default();
        v.sort();
        v
    }

    /// Sends entry `entry` to `peer` and removes it once every file is stored.
    pub fn send(&self, client: &Client, peer: &Peer, entry: &Path) -> Result<Vec<Stored>, PacsError> {
        let files = dicom_files(entry);
        let stored = store(client, peer, &files)?;
        let _ = std::fs::remove_dir_all(entry);
        Ok(stored)
    }

    /// Sends every entry to `peer`, oldest first, calling `sent` after each one stored; the
    /// first failure stops it (that entry and the later ones stay queued) and is returned with
    /// its entry.
    pub fn send_all(
        &self,
        client: &Client,
        peer: &Peer,
        mut sent: impl FnMut(&Path, &[Stored]),
    ) -> Result<(), Box<(PathBuf, PacsError)>> {
        for entry in self.entries() {
            let stored = self.send(client, peer, &entry).map_err(|e| Box::new((entry.clone(), e)))?;
            sent(&entry, &stored);
        }
        Ok(())
    }
}

/// A queue entry's name, for messages.
pub fn entry_name(entry: &Path) -> std::borrow::Cow<'_, str> {
    entry.file_name().unwrap_or_default().to_string_lossy()
}

/// The `.dcm` files in `dir` and its folders (but a PACS queue's), sorted; `dir` itself if it
/// is a file.
pub fn dicom_files(dir: &Path) -> Vec<PathBuf> {
    if dir.is_file() {
        return vec![dir.to_path_buf()];
    }
    let mut v = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else { continue };
        for e in rd.filter_map(Result::ok) {
            let p = e.path();
            if e.file_name().to_string_lossy().starts_with('.') {
                continue;
            }
            if p.is_dir() {
                // A queue inside (a reconstruction's pacs_queue) holds copies: not sent twice.
                if !Queue::is_queue(&p) {
                    stack.push(p);
                }
            } else if p.extension().is_some_and(|x| x.eq_ignore_ascii_case("dcm")) {
                v.push(p);
            }
        }
    }
    v.sort();
    v
}

/// Counts of a [`Sender`]'s work.
#[derive(Debug, Default)]
pub struct SenderCounts {
    /// Scans stored.
    pub sent: AtomicU64,
    /// Attempts that failed.
    pub failures: AtomicU64,
}

/// Sends a [`Queue`] to a PACS on a thread of its own (see the module's notes).
pub struct Sender {
    wake: Option<mpsc::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
    counts: Arc<SenderCounts>,
}

impl Sender {
    /// Starts sending `queue` to `peer` as `client`; what is already queued goes first.
    pub fn spawn(queue: Queue, client: Client, peer: Peer) -> Sender {
        let (tx, rx) = mpsc::channel::<()>();
        let counts = Arc::new(SenderCounts::default());
        let c = counts.clone();
        let thread = std::thread::Builder::new()
            .name("pacs-sender".into())
            .spawn(move || {
                let mut backoff = Duration::from_secs(1);
                loop {
                    let result = queue.send_all(&client, &peer, |entry, stored| {
                        c.sent.fetch_add(1, Ordering::Relaxed);
                        backoff = Duration::from_secs(1);
                        log::info!("pacs: {} sent to {peer}: {} instance(s) stored", entry_name(entry), stored.len());
                    });
                    let failed = result.is_err();
                    if let Err(failure) = result {
                        let (entry, e) = *failure;
                        c.failures.fetch_add(1, Ordering::Relaxed);
                        log::error!(
                            "pacs: {} stays queued in {} (next try in {} s): {e}",
                            entry_name(&entry),
                            queue.dir().display(),
                            backoff.as_secs()
                        );
                    }
                    let wait = if failed { backoff } else { Duration::from_secs(3600) };
                    if failed {
                        backoff = (backoff * 2).min(Duration::from_secs(60));
                    }
                    match rx.recv_timeout(wait) {
                        Ok(()) | Err(mpsc::RecvTimeoutError::Timeout) => {}
                        Err(mpsc::RecvTimeoutError::Disconnected) => return,
                    }
                }
            })
            .ok();
        Sender { wake: Some(tx), thread, counts }
    }

    /// Tells the thread that an entry was queued.
    pub fn wake(&self) {
        if let Some(w) = &self.wake {
            let _ = w.send(());
        }
    }

    /// The counts so far.
    pub fn counts(&self) -> &SenderCounts {
        &self.counts
    }
}

impl Drop for Sender {
    fn drop(&mut self) {
        // Closing the channel ends the thread after its current attempt; a scan still queued
        // stays on disk for the next start.
        self.wake = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_response_status_is_read_with_every_length_checked() {
        let el =
            |e: u16, v: &[u8]| [&0u16.to_le_bytes()[..], &e.to_le_bytes(), &(v.len() as u32).to_le_bytes(), v].concat();
        let ok =
            [el(0x0000, &[0; 4]), el(0x0100, &0x8001u16.to_le_bytes()), el(0x0900, &0xA700u16.to_le_bytes())].concat();
        assert_eq!(command_status(&ok), Ok(0xA700));
        assert!(command_status(&ok[..ok.len() - 1]).unwrap_err().contains("says 2 bytes; 1 are left"));
        let mut huge = el(0x0100, &[1, 0]);
        huge[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(command_status(&huge).unwrap_err().contains("byte offset 0 says 4294967295 bytes"));
        assert!(command_status(&el(0x0100, &[1, 0])).unwrap_err().contains("without a Status"));
        assert!(command_status(&[8, 0, 0x16, 0, 0, 0, 0, 0]).unwrap_err().contains("not of the command set"));
    }

    #[test]
    fn addresses_and_titles() {
        let p: Peer = "ORTHANC@127.0.0.1:4242".parse().unwrap();
        assert_eq!(p, Peer { ae_title: "ORTHANC".into(), host: "127.0.0.1".into(), port: 4242 });
        assert_eq!(p.to_string(), "ORTHANC@127.0.0.1:4242");
        let v6: Peer = "PACS@[::1]:104".parse().unwrap();
        assert_eq!((v6.host.as_str(), v6.to_string().as_str()), ("::1", "PACS@[::1]:104"));
        for (bad, says) in [
            ("127.0.0.1:104", "expected AET@host:port"),
            ("PACS@host", "no port"),
            ("PACS@host:0", "not 1..65535"),
            ("PACS@host:99999", "not 1..65535"),
            ("@host:104", "not empty"),
            ("A_TITLE_LONGER_THAN_16@h:1", "at most 16"),
            ("BAD\\AE@h:1", "holds"),
        ] {
            let e = bad.parse::<Peer>().unwrap_err();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }

    #[test]
    fn a_queue_entry_appears_whole_and_goes_in_order() {
        let d = std::env::temp_dir().join(format!("xsurf-pacs-queue-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        let f = d.join("surface.dcm");
        std::fs::write(&f, b"x").unwrap();
        let q = Queue::open(&d.join("q")).unwrap();
        assert!(Queue::is_queue(q.dir()));
        q.enqueue("0002-scan_2", std::slice::from_ref(&f)).unwrap();
        q.enqueue("0001-scan_1", std::slice::from_ref(&f)).unwrap();
        q.enqueue("0001-scan_1", std::slice::from_ref(&f)).unwrap();
        let e = q.entries();
        assert_eq!(
            e.iter().map(|p| p.file_name().unwrap().to_str().unwrap()).collect::<Vec<_>>(),
            ["0001-scan_1", "0002-scan_2"]
        );
        assert_eq!(dicom_files(&e[0]), vec![e[0].join("surface.dcm")]);
        // Nobody listens on port 9 of loopback: an error naming the PACS, and the entry stays.
        let peer: Peer = "NOBODY@127.0.0.1:9".parse().unwrap();
        let client = Client { calling: "XSURF".into(), timeout: Duration::from_secs(2) };
        let err = q.send(&client, &peer, &e[0]).unwrap_err().to_string();
        assert!(err.contains("surface.dcm") || err.contains("NOBODY@127.0.0.1:9"), "{err}");
        assert_eq!(q.entries().len(), 2);
        std::fs::remove_dir_all(&d).unwrap();
    }
}
