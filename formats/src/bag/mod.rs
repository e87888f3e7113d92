//! rosbag2 bags with MCAP storage: a directory with `metadata.yaml` (we write version 8, which
//! Humble and Jazzy both read; we read versions 5 to 9) and `<name>_0.mcap` (profile `ros2`,
//! `ros2msg` schemas, `cdr` messages, optional zstd chunk compression).

use crate::FileError;
use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};

/// Why a bag cannot be written or read.
#[derive(Debug, thiserror::Error)]
pub enum BagError {
    /// A file could not be read or written.
    #[error(transparent)]
    File(#[from] FileError),
    /// The output directory exists and is not empty.
    #[error("{0}: bag directory exists and is not empty")]
    Exists(PathBuf),
    /// `metadata.yaml` is missing or malformed.
    #[error("{path}: {reason}")]
    Metadata {
        /// The metadata file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The MCAP data is malformed or ends early.
    #[error("{path}: MCAP error at byte offset {offset}: {reason}")]
    Mcap {
        /// The MCAP file.
        path: PathBuf,
        /// Bytes read when the error was found.
        offset: u64,
        /// What is wrong.
        reason: String,
    },
    /// The MCAP file could not be written (a full disk, say); what was written before the
    /// last complete chunk stays readable.
    #[error("{path}: cannot write: {reason}")]
    McapWrite {
        /// The MCAP file.
        path: PathBuf,
        /// What went wrong, with its cause.
        reason: String,
    },
    /// A message names a topic that was not added.
    #[error("topic {0} was not added to the bag")]
    UnknownTopic(String),
    /// The bag uses something we do not read.
    #[error("{path}: {reason}")]
    Unsupported {
        /// The bag or file.
        path: PathBuf,
        /// What is not supported.
        reason: String,
    },
}

/// The QoS a topic was offered with, as rosbag2 records it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    /// Reliable (else best effort).
    pub reliable: bool,
    /// Transient local (else volatile).
    pub transient_local: bool,
    /// History depth (keep last).
    pub depth: u32,
}

impl Qos {
    /// Reliable, volatile, depth 10: clouds, meshes, events, tf.
    pub const RELIABLE: Qos = Qos { reliable: true, transient_local: false, depth: 10 };
    /// Best effort, volatile, depth 5: camera streams.
    pub const SENSOR: Qos = Qos { reliable: false, transient_local: false, depth: 5 };
    /// Reliable, transient local, depth 1: `/tf_static`.
    pub const STATIC: Qos = Qos { reliable: true, transient_local: true, depth: 1 };

    /// The `offered_qos_profiles` string of metadata version 8 (integer enums), also used as
    /// the MCAP channel's metadata so the two agree.
    pub fn to_yaml_string(&self) -> String {
        format!(
            "- history: 1\n  depth: {}\n  reliability: {}\n  durability: {}\n  deadline:\n    sec: 9223372036\n    nsec: 854775807\n  lifespan:\n    sec: 9223372036\n    nsec: 854775807\n  liveliness: 1\n  liveliness_lease_duration:\n    sec: 9223372036\n    nsec: 854775807\n  avoid_ros_namespace_conventions: false",
            self.depth,
            if self.reliable { 1 } else { 2 },
            if self.transient_local { 1 } else { 2 }
        )
    }

    /// Parses the first profile of an `offered_qos_profiles` value: the version 4-8 string form
    /// (integer enums) or the version 9 list form (string enums). Unknown fields keep defaults.
    pub fn from_metadata(v: &serde_yaml::Value) -> Option<Qos> {
        let parsed;
        let list = match v {
            serde_yaml::Value::String(s) if s.trim().is_empty() => return None,
            serde_yaml::Value::String(s) => {
                parsed = serde_yaml::from_str::<serde_yaml::Value>(s).ok()?;
                &parsed
            }
            other => other,
        };
        let p = list.as_sequence()?.first()?;
        let field = |k: &str| p.get(k);
        let reliable = match field("reliability") {
            Some(serde_yaml::Value::Number(n)) => n.as_u64() != Some(2),
            Some(serde_yaml::Value::String(s)) => s != "best_effort",
            _ => true,
        };
        let transient_local = match field("durability") {
            Some(serde_yaml::Value::Number(n)) => n.as_u64() == Some(1),
            Some(serde_yaml::Value::String(s)) => s == "transient_local",
            _ => false,
        };
        let depth = field("depth").and_then(serde_yaml::Value::as_u64).unwrap_or(10) as u32;
        Some(Qos { reliable, transient_local, depth })
    }
}

/// Options of a new bag.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BagOptions {
    /// Compress MCAP chunks with zstd.
    pub zstd: bool,
}

struct TopicRecord {
    name: String,
    type_name: String,
    qos: String,
    channel: u16,
    count: u64,
}

/// Writes a rosbag2 directory.
pub struct BagWriter {
    dir: PathBuf,
    file_name: String,
    mcap: mcap::Writer<std::io::BufWriter<std::fs::File>>,
    topics: Vec<TopicRecord>,
    by_name: HashMap<String, usize>,
    schemas: HashMap<String, u16>,
    start_ns: Option<u64>,
    end_ns: u64,
    count: u64,
}

fn mcap_err(path: &Path, offset: u64, e: impl std::fmt::Display) -> BagError {
    BagError::Mcap { path: path.to_path_buf(), offset, reason: e.to_string() }
}

/// A failed write, with the causes the mcap crate wraps ("I/O error from writing": which one).
fn write_err(path: &Path, e: &mcap::McapError) -> BagError {
    let mut reason = e.to_string();
    let mut source = std::error::Error::source(e);
    while let Some(s) = source {
        reason.push_str(&format!(": {s}"));
        source = s.source();
    }
    BagError::McapWrite { path: path.to_path_buf(), reason }
}

impl BagWriter {
    /// Creates the bag directory (which must not exist or be empty) and its MCAP file.
    pub fn create(dir: &Path, options: BagOptions) -> Result<Self, BagError> {
        let stem = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "bag".into());
        Self::create_with_stem(dir, &stem, options)
    }

    /// As [`BagWriter::create`], with the storage file named `<stem>_0.mcap` whatever the
    /// folder is called (a bag written under a temporary name and renamed when complete).
    pub fn create_with_stem(dir: &Path, stem: &str, options: BagOptions) -> Result<Self, BagError> {
        if dir.exists() {
            let empty = std::fs::read_dir(dir).map_err(|e| FileError::new(dir, e))?.next().is_none();
            if !empty {
                return Err(BagError::Exists(dir.to_path_buf()));
            }
        }
        std::fs::create_dir_all(dir).map_err(|e| FileError::new(dir, e))?;
        let file_name = format!("{stem}_0.mcap");
        let path = dir.join(&file_name);
        let file = std::fs::File::create(&path).map_err(|e| FileError::new(&path, e))?;
        let opts = mcap::WriteOptions::new()
            .profile("ros2")
            .library("xsurf")
            .compression(options.zstd.then_some(mcap::Compression::Zstd));
        let mcap = opts.create(std::io::BufWriter::new(file)).map_err(|e| write_err(&path, &e))?;
        Ok(Self {
            dir: dir.to_path_buf(),
            file_name,
            mcap,
            topics: Vec::new(),
            by_name: HashMap::new(),
            schemas: HashMap::new(),
            start_ns: None,
            end_ns: 0,
            count: 0,
        })
    }

    /// Adds a topic (once; adding it again is a no-op).
    pub fn add_topic(&mut self, name: &str, type_name: &str, definition: &str, qos: &Qos) -> Result<(), BagError> {
        if self.by_name.contains_key(name) {
            return Ok(());
        }
        let path = self.dir.join(&self.file_name);
        let schema = match self.schemas.get(type_name) {
            Some(&id) => id,
            None => {
                let id = self
                    .mcap
                    .add_schema(type_name, "ros2msg", definition.as_bytes())
                    .map_err(|e| write_err(&path, &e))?;
                self.schemas.insert(type_name.to_string(), id);
                id
            }
        };
        let qos = qos.to_yaml_string();
        let mut meta = BTreeMap::new();
        meta.insert("offered_qos_profiles".to_string(), qos.clone());
        let channel = self.mcap.add_channel(schema, name, "cdr", &meta).map_err(|e| write_err(&path, &e))?;
        self.by_name.insert(name.to_string(), self.topics.len());
        self.topics.push(TopicRecord { name: name.into(), type_name: type_name.into(), qos, channel, count: 0 });
        Ok(())
    }

    /// Writes one CDR message (with its 4-byte header) on a topic added before.
    pub fn write(&mut self, topic: &str, log_time_ns: u64, publish_time_ns: u64, data: &[u8]) -> Result<(), BagError> {
        let &i = self.by_name.get(topic).ok_or_else(|| BagError::UnknownTopic(topic.to_string()))?;
        let t = &mut self.topics[i];
        let header = mcap::records::MessageHeader {
            channel_id: t.channel,
            sequence: 0,
            log_time: log_time_ns,
            publish_time: publish_time_ns,
        };
        self.mcap.write_to_known_channel(&header, data).map_err(|e| write_err(&self.dir.join(&self.file_name), &e))?;
        t.count += 1;
        self.count += 1;
        self.start_ns = Some(self.start_ns.map_or(log_time_ns, |s| s.min(log_time_ns)));
        self.end_ns = self.end_ns.max(log_time_ns);
        Ok(())
    }

    /// Finishes the MCAP file and writes `metadata.yaml` (atomically). Returns the metadata.
    pub fn finish(mut self) -> Result<BagMetadata, BagError> {
        let path = self.dir.join(&self.file_name);
        self.mcap.finish().map_err(|e| write_err(&path, &e))?;
        let start = self.start_ns.unwrap_or(0);
        let meta = BagMetadata {
            version: 8,
            storage_identifier: "mcap".into(),
            start_ns: start,
            // rosbags only returns messages inside [start, start + duration]: make it inclusive.
            duration_ns: if self.count > 0 { self.end_ns - start + 1 } else { 0 },
            message_count: self.count,
            topics: self
                .topics
                .iter()
                .map(|t| TopicMetadata {
                    name: t.name.clone(),
                    type_name: t.type_name.clone(),
                    serialization_format: "cdr".into(),
                    qos: Qos::from_metadata(&serde_yaml::Value::String(t.qos.clone())),
                    qos_text: t.qos.clone(),
                    message_count: t.count,
                })
                .collect(),
            files: vec![self.file_name.clone()],
            file_spans: vec![FileSpan {
                start_ns: start,
                duration_ns: if self.count > 0 { self.end_ns - start + 1 } else { 0 },
                message_count: self.count,
            }],
            // rosbag2 records MCAP chunk compression only in the storage preset, not here.
            compression: String::new(),
            ros_distro: "jazzy".into(),
        };
        crate::write_bytes_atomic(&self.dir.join("metadata.yaml"), meta.to_yaml().as_bytes())?;
        Ok(meta)
    }
}

/// One topic of a bag.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicMetadata {
    /// Topic name.
    pub name: String,
    /// ROS 2 type, `pkg/msg/Type`.
    pub type_name: String,
    /// `cdr`.
    pub serialization_format: String,
    /// The first offered QoS profile, when recorded.
    pub qos: Option<Qos>,
    /// The QoS as stored (version 8 string form).
    pub qos_text: String,
    /// Messages on the topic.
    pub message_count: u64,
}

/// One storage file's messages: its first stamp, span and count (metadata.yaml `files`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FileSpan {
    /// First message, ns since the epoch.
    pub start_ns: u64,
    /// Last minus first, ns.
    pub duration_ns: u64,
    /// Messages in the file.
    pub message_count: u64,
}

/// The contents of `metadata.yaml`.
#[derive(Debug, Clone, PartialEq)]
pub struct BagMetadata {
    /// Metadata version (5..=9 read, 8 written).
    pub version: u64,
    /// `mcap`.
    pub storage_identifier: String,
    /// First message, ns since the epoch.
    pub start_ns: u64,
    /// Duration, ns.
    pub duration_ns: u64,
    /// Total messages.
    pub message_count: u64,
    /// Topics.
    pub topics: Vec<TopicMetadata>,
    /// Storage files, relative to the bag directory.
    pub files: Vec<String>,
    /// Each storage file's own first stamp, span and message count, where known (a reindexed
    /// bag of several files); empty: the bag's figures stand for its one file.
    pub file_spans: Vec<FileSpan>,
    /// How the data is compressed, for display.
    pub compression: String,
    /// ROS distribution that wrote the bag.
    pub ros_distro: String,
}

fn yaml_str(s: &str) -> String {
    serde_json::to_string(s).unwrap_or_else(|_| "\"\"".into())
}

impl BagMetadata {
    /// Renders version 8 `metadata.yaml`.
    pub fn to_yaml(&self) -> String {
        let mut y = String::new();
        let _ = writeln!(y, "rosbag2_bagfile_information:\n  version: 8\n  storage_identifier: mcap");
        let _ = writeln!(y, "  duration:\n    nanoseconds: {}", self.duration_ns);
        let _ = writeln!(y, "  starting_time:\n    nanoseconds_since_epoch: {}", self.start_ns);
        let _ = writeln!(y, "  message_count: {}\n  topics_with_message_count:", self.message_count);
        for t in &self.topics {
            let _ = writeln!(
                y,
                "    - topic_metadata:\n        name: {}\n        type: {}\n        serialization_format: {}\n        offered_qos_profiles: {}\n        type_description_hash: \"\"\n      message_count: {}",
                yaml_str(&t.name),
                yaml_str(&t.type_name),
                yaml_str(&t.serialization_format),
                yaml_str(&t.qos_text),
                t.message_count
            );
        }
        let _ = writeln!(y, "  compression_format: \"\"\n  compression_mode: \"\"\n  relative_file_paths:");
        for f in &self.files {
            let _ = writeln!(y, "    - {}", yaml_str(f));
        }
        let _ = writeln!(y, "  files:");
        let whole =
            FileSpan { start_ns: self.start_ns, duration_ns: self.duration_ns, message_count: self.message_count };
        for (i, f) in self.files.iter().enumerate() {
            let span = self.file_spans.get(i).copied().unwrap_or(whole);
            let _ = writeln!(
                y,
                "    - path: {}\n      starting_time:\n        nanoseconds_since_epoch: {}\n      duration:\n        nanoseconds: {}\n      message_count: {}",
                yaml_str(f),
                span.start_ns,
                span.duration_ns,
                span.message_count
            );
        }
        let _ = writeln!(y, "  custom_data: ~\n  ros_distro: {}", yaml_str(&self.ros_distro));
        y
    }

    /// Parses `metadata.yaml` text (versions 5 to 9). `path` names the file in errors.
    pub fn parse(text: &str, path: &Path) -> Result<BagMetadata, BagError> {
        let err = |reason: String| BagError::Metadata { path: path.to_path_buf(), reason };
        let root: serde_yaml::Value = serde_yaml::from_str(text).map_err(|e| err(format!("not YAML: {e}")))?;
        let info =
            root.get("rosbag2_bagfile_information").ok_or_else(|| err("no rosbag2_bagfile_information".into()))?;
        let version = yaml_u64(info.get("version"), "version").map_err(err)?;
        if !(1..=9).contains(&version) {
            return Err(err(format!("metadata version {version} is not supported (1 to 9)")));
        }
        let (storage, compression) =
            Self::check_storage(info).map_err(|reason| BagError::Unsupported { path: path.to_path_buf(), reason })?;
        let start_ns =
            yaml_u64(info.get("starting_time").and_then(|s| s.get("nanoseconds_since_epoch")), "starting_time")
                .map_err(err)?;
        let duration_ns = yaml_u64(info.get("duration").and_then(|s| s.get("nanoseconds")), "duration").map_err(err)?;
        let message_count = yaml_u64(info.get("message_count"), "message_count").map_err(err)?;
        let topics = Self::parse_topics(info).map_err(err)?;
        let files: Vec<String> = info
            .get("relative_file_paths")
            .and_then(serde_yaml::Value::as_sequence)
            .ok_or_else(|| err("missing relative_file_paths".into()))?
            .iter()
            .filter_map(|f| f.as_str().map(str::to_string))
            .collect();
        if files.is_empty() {
            return Err(err("relative_file_paths is empty".into()));
        }
        Ok(BagMetadata {
            version,
            storage_identifier: storage,
            start_ns,
            duration_ns,
            message_count,
            topics,
            file_spans: Self::parse_file_spans(info, files.len()),
            files,
            compression,
            ros_distro: info.get("ros_distro").and_then(serde_yaml::Value::as_str).unwrap_or("").to_string(),
        })
    }

    /// The storage (only mcap is read) and compression format (none, or only per-message
    /// compression marked NONE, is read) of the bag's `info`; what is unsupported otherwise.
    fn check_storage(info: &serde_yaml::Value) -> Result<(String, String), String> {
        let storage = info.get("storage_identifier").and_then(serde_yaml::Value::as_str).unwrap_or("").to_string();
        if storage != "mcap" {
            return Err(format!(
                "storage {storage:?}: only mcap bags are read (convert sqlite3 bags with `ros2 bag convert`)"
            ));
        }
        let compression_mode = info.get("compression_mode").and_then(serde_yaml::Value::as_str).unwrap_or("");
        let compression_format = info.get("compression_format").and_then(serde_yaml::Value::as_str).unwrap_or("");
        if !compression_mode.is_empty() && compression_mode != "NONE" {
            return Err(format!(
                "{compression_mode} {compression_format} compression (decompress with `ros2 bag decompress`)"
            ));
        }
        Ok((storage, compression_format.to_string()))
    }

    /// The topics of `topics_with_message_count`.
    fn parse_topics(info: &serde_yaml::Value) -> Result<Vec<TopicMetadata>, String> {
        let list = info
            .get("topics_with_message_count")
            .and_then(serde_yaml::Value::as_sequence)
            .ok_or("missing topics_with_message_count")?;
        let mut topics = Vec::new();
        for (i, t) in list.iter().enumerate() {
            let m = t.get("topic_metadata").ok_or_else(|| format!("topic {i}: no topic_metadata"))?;
            let s = |k: &str| m.get(k).and_then(serde_yaml::Value::as_str).map(str::to_string);
            let qos_value = m.get("offered_qos_profiles").cloned().unwrap_or(serde_yaml::Value::Null);
            topics.push(TopicMetadata {
                name: s("name").ok_or_else(|| format!("topic {i}: no name"))?,
                type_name: s("type").ok_or_else(|| format!("topic {i}: no type"))?,
                serialization_format: s("serialization_format").unwrap_or_else(|| "cdr".into()),
                qos: Qos::from_metadata(&qos_value),
                qos_text: qos_value.as_str().unwrap_or("").to_string(),
                message_count: yaml_u64(t.get("message_count"), &format!("topic {i} message_count"))?,
            });
        }
        Ok(topics)
    }

    /// Each of the `files` storage files' own span, where the `files` list (version 5 on) gives
    /// one per file; none otherwise.
    fn parse_file_spans(info: &serde_yaml::Value, files: usize) -> Vec<FileSpan> {
        info.get("files")
            .and_then(serde_yaml::Value::as_sequence)
            .map(|list| {
                list.iter()
                    .filter_map(|f| {
                        Some(FileSpan {
                            start_ns: f.get("starting_time")?.get("nanoseconds_since_epoch")?.as_u64()?,
                            duration_ns: f.get("duration")?.get("nanoseconds")?.as_u64()?,
                            message_count: f.get("message_count")?.as_u64()?,
                        })
                    })
                    .collect()
            })
            .filter(|spans: &Vec<FileSpan>| spans.len() == files)
            .unwrap_or_default()
    }
}

/// A number of `metadata.yaml`, or what is wrong with it (`what` names it).
fn yaml_u64(v: Option<&serde_yaml::Value>, what: &str) -> Result<u64, String> {
    v.and_then(serde_yaml::Value::as_u64).ok_or_else(|| format!("missing or non-numeric {what}"))
}

/// What [`reindex`] found.
#[derive(Debug, Clone)]
pub struct Reindexed {
    /// The metadata written.
    pub metadata: BagMetadata,
    /// Files that ended early (a recording killed before it finished): the file and the error;
    /// their messages before it are counted.
    pub cut: Vec<String>,
}

/// The storage files of a bag folder in rosbag2's order: `<name>_<N>.mcap` by N, then others
/// by name.
fn storage_files(dir: &Path) -> Result<Vec<String>, BagError> {
    let rd = std::fs::read_dir(dir).map_err(|e| FileError::new(dir, e))?;
    let mut names: Vec<String> = Vec::new();
    let mut other = Vec::new();
    for e in rd {
        let name = e.map_err(|e| FileError::new(dir, e))?.file_name().to_string_lossy().into_owned();
        if name.ends_with(".mcap") {
            names.push(name);
        } else if name.ends_with(".db3") {
            other.push(name);
        }
    }
    if names.is_empty() {
        return Err(match other.first() {
            Some(db) => BagError::Unsupported {
                path: dir.join(db),
                reason: "sqlite3 storage: only mcap bags are read (convert it with `ros2 bag convert`)".into(),
            },
            None => BagError::Metadata { path: dir.to_path_buf(), reason: "no .mcap storage file to index".into() },
        });
    }
    let index = |n: &str| -> Option<u64> { n.strip_suffix(".mcap")?.rsplit_once('_')?.1.parse().ok() };
    names.sort_by(|a, b| (index(a).is_none(), index(a), a).cmp(&(index(b).is_none(), index(b), b)));
    Ok(names)
}

/// Writes the `metadata.yaml` of a bag folder that has none (split files left by a recorder
/// that was killed, or copied without it), as `ros2 bag reindex` does: every MCAP storage file
/// is read through, in rosbag2's order, for its topics (type, serialization, the offered QoS
/// from the channel's metadata), message counts and times. A file that ends early is counted up
/// to its last complete message and reported in [`Reindexed::cut`]. An existing metadata.yaml is
/// replaced only with `overwrite`.
pub fn reindex(dir: &Path, overwrite: bool) -> Result<Reindexed, BagError> {
    let meta_path = dir.join("metadata.yaml");
    if !dir.is_dir() {
        return Err(BagError::Metadata { path: dir.to_path_buf(), reason: "not a folder".into() });
    }
    if meta_path.exists() && !overwrite {
        return Err(BagError::Metadata {
            path: meta_path,
            reason: "exists already (reindex replaces it only when asked: --force)".into(),
        });
    }
    let r = index(dir)?;
    crate::write_bytes_atomic(&meta_path, r.metadata.to_yaml().as_bytes())?;
    Ok(r)
}

/// The metadata of a bag folder from its MCAP storage files alone (see [`reindex`]).
pub fn index(dir: &Path) -> Result<Reindexed, BagError> {
    let files = storage_files(dir)?;
    let mut topics: Vec<TopicMetadata> = Vec::new();
    let mut spans = Vec::new();
    let mut cut = Vec::new();
    for f in &files {
        let path = dir.join(f);
        let file = std::fs::File::open(&path).map_err(|e| FileError::new(&path, e))?;
        let count = std::rc::Rc::new(std::cell::Cell::new(0));
        let reader = message_reader(file, &count);
        let (mut first, mut last, mut n) = (u64::MAX, 0u64, 0u64);
        for m in reader {
            let m = match m {
                Ok(m) => m,
                Err(e) => {
                    cut.push(mcap_err(&path, count.get(), e).to_string());
                    break;
                }
            };
            first = first.min(m.log_time);
            last = last.max(m.log_time);
            n += 1;
            let topic = &m.channel.topic;
            match topics.iter_mut().find(|t| &t.name == topic) {
                Some(t) => t.message_count += 1,
                None => {
                    let qos_text = m.channel.metadata.get("offered_qos_profiles").cloned().unwrap_or_default();
                    topics.push(TopicMetadata {
                        name: topic.clone(),
                        type_name: m.channel.schema.as_ref().map(|s| s.name.clone()).unwrap_or_default(),
                        serialization_format: m.channel.message_encoding.clone(),
                        qos: Qos::from_metadata(&serde_yaml::Value::String(qos_text.clone())),
                        qos_text,
                        message_count: 1,
                    });
                }
            }
        }
        spans.push(if n > 0 {
            FileSpan { start_ns: first, duration_ns: last - first, message_count: n }
        } else {
            FileSpan::default()
        });
    }
    let counted: Vec<&FileSpan> = spans.iter().filter(|s| s.message_count > 0).collect();
    let start_ns = counted.iter().map(|s| s.start_ns).min().unwrap_or(0);
    let end_ns = counted.iter().map(|s| s.start_ns + s.duration_ns).max().unwrap_or(0);
    let message_count = spans.iter().map(|s| s.message_count).sum();
    let metadata = BagMetadata {
        version: 8,
        storage_identifier: "mcap".into(),
        start_ns,
        // Inclusive of the last message, as the writer makes it (rosbags reads [start, start + duration]).
        duration_ns: if message_count > 0 { end_ns - start_ns + 1 } else { 0 },
        message_count,
        topics,
        files,
        file_spans: spans,
        compression: String::new(),
        ros_distro: String::new(),
    };
    Ok(Reindexed { metadata, cut })
}

/// One message read from a bag.
#[derive(Debug, Clone)]
pub struct RawMessage {
    /// Topic.
    pub topic: String,
    /// ROS 2 type (from the MCAP schema).
    pub type_name: String,
    /// Receive time, ns.
    pub log_time_ns: u64,
    /// Send time, ns.
    pub publish_time_ns: u64,
    /// CDR payload with its 4-byte header.
    pub data: Vec<u8>,
}

/// An opened bag.
#[derive(Debug, Clone)]
pub struct Bag {
    /// The directory.
    pub dir: PathBuf,
    /// Its metadata.
    pub metadata: BagMetadata,
    /// Set when the folder had no metadata.yaml and the metadata was read from the storage
    /// files (a recorder killed before it wrote one): what was cut short, if anything.
    pub indexed: Option<Vec<String>>,
}

impl Bag {
    /// Opens a bag directory by reading its `metadata.yaml`.
    pub fn open(dir: &Path) -> Result<Bag, BagError> {
        let path = dir.join("metadata.yaml");
        if !dir.is_dir() {
            return Err(BagError::Metadata { path: dir.to_path_buf(), reason: "not a bag directory".into() });
        }
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            // No metadata.yaml beside MCAP files (a recorder killed before it wrote it): read
            // the files themselves, up to their last whole chunk, nothing written.
            Err(e) if e.kind() == std::io::ErrorKind::NotFound && storage_files(dir).is_ok() => {
                let r = index(dir)?;
                if r.metadata.message_count == 0 {
                    if let Some(first) = r.cut.first() {
                        // Nothing readable at all: not a bag, whatever the files are called.
                        return Err(BagError::Metadata {
                            path: path.clone(),
                            reason: format!("does not exist, and the storage files hold no message: {first}"),
                        });
                    }
                }
                return Ok(Bag { dir: dir.to_path_buf(), metadata: r.metadata, indexed: Some(r.cut) });
            }
            Err(e) => return Err(BagError::Metadata { path: path.clone(), reason: format!("cannot read: {e}") }),
        };
        let metadata = BagMetadata::parse(&text, &path)?;
        for f in &metadata.files {
            if !dir.join(f).is_file() {
                return Err(BagError::Metadata { path, reason: format!("lists file {f}, which does not exist") });
            }
        }
        Ok(Bag { dir: dir.to_path_buf(), metadata, indexed: None })
    }

    /// Checks that every storage file is a whole MCAP file: the magic at its start and at its
    /// end (a bag cut short, or bytes that are not MCAP, are named with the offset).
    pub fn verify_storage(&self) -> Result<(), BagError> {
        use std::io::{Read, Seek, SeekFrom};
        const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";
        for f in &self.metadata.files {
            let path = self.dir.join(f);
            let bad = |offset: u64, reason: String| BagError::Mcap { path: path.clone(), offset, reason };
            let mut file = std::fs::File::open(&path).map_err(|e| FileError::new(&path, e))?;
            let len = file.metadata().map_err(|e| FileError::new(&path, e))?.len();
            if len < 16 {
                return Err(bad(0, format!("{len} bytes: too short for an MCAP file")));
            }
            let mut head = [0u8; 8];
            file.read_exact(&mut head).map_err(|e| FileError::new(&path, e))?;
            if &head != MAGIC {
                return Err(bad(0, "does not start with the MCAP magic: not an MCAP file".into()));
            }
            let mut tail = [0u8; 8];
            file.seek(SeekFrom::End(-8)).map_err(|e| FileError::new(&path, e))?;
            file.read_exact(&mut tail).map_err(|e| FileError::new(&path, e))?;
            if &tail != MAGIC {
                return Err(bad(
                    len - 8,
                    "no MCAP magic at the end: the file is cut short (a recording that did not finish)".into(),
                ));
            }
        }
        Ok(())
    }

    /// Total size of the storage files, bytes.
    pub fn size_bytes(&self) -> u64 {
        self.metadata.files.iter().filter_map(|f| std::fs::metadata(self.dir.join(f)).ok()).map(|m| m.len()).sum()
    }

    /// Every message in file order. After an error (a truncated or corrupt file) the iterator
    /// ends; the messages before it have been returned.
    pub fn messages(&self) -> BagMessages {
        let files = self.metadata.files.iter().map(|f| self.dir.join(f)).collect();
        BagMessages::new(files, xsurf_core::par::threads())
    }

    /// The same, read and decompressed on the calling thread alone.
    pub fn messages_here(&self) -> BagMessages {
        BagMessages::new(self.metadata.files.iter().map(|f| self.dir.join(f)).collect(), 0)
    }

    /// A `ros2 bag info`-style summary.
    pub fn info(&self) -> String {
        let m = &self.metadata;
        let mut s = String::new();
        let secs = |ns: u64| ns as f64 * 1e-9;
        let _ = writeln!(s, "Files:             {}", m.files.join(", "));
        let _ = writeln!(s, "Bag size:          {:.1} MiB", self.size_bytes() as f64 / (1024.0 * 1024.0));
        let _ = writeln!(s, "Storage id:        {} (metadata version {})", m.storage_identifier, m.version);
        let _ = writeln!(s, "ROS Distro:        {}", if m.ros_distro.is_empty() { "unknown" } else { &m.ros_distro });
        let _ = writeln!(s, "Duration:          {:.3}s", secs(m.duration_ns));
        // From the integer nanoseconds: an f64 of seconds since 1970 keeps only about 0.1 us.
        let stamp = |ns: u64| format!("{}.{:09}", ns / 1_000_000_000, ns % 1_000_000_000);
        let _ = writeln!(s, "Start:             {} (s since epoch)", stamp(m.start_ns));
        let _ = writeln!(s, "End:               {} (s since epoch)", stamp(m.start_ns + m.duration_ns));
        let _ = writeln!(s, "Messages:          {}", m.message_count);
        let w = m.topics.iter().map(|t| t.name.len()).max().unwrap_or(0);
        for (i, t) in m.topics.iter().enumerate() {
            let qos = t.qos.map_or("unknown".to_string(), |q| {
                format!(
                    "{} {} depth {}",
                    if q.reliable { "reliable" } else { "best_effort" },
                    if q.transient_local { "transient_local" } else { "volatile" },
                    q.depth
                )
            });
            let _ = writeln!(
                s,
                "{}Topic: {:w$} | Type: {} | Count: {} | Serialization Format: {} | QoS: {}",
                if i == 0 { "Topic information: " } else { "                   " },
                t.name,
                t.type_name,
                t.message_count,
                t.serialization_format,
                qos
            );
        }
        s
    }
}

/// Counts the bytes read through it, so that errors can name a file offset.
struct Counting<R> {
    inner: R,
    count: std::rc::Rc<std::cell::Cell<u64>>,
}
impl<R: Read> Read for Counting<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.count.set(self.count.get() + n as u64);
        Ok(n)
    }
}

/// The longest MCAP record (or decompressed chunk) read from a file of `file_len` bytes: 256
/// times the file, at least 64 MiB and at most 1 GiB. A length field beyond it is a damaged
/// file, refused by the reader, not an allocation of that size (found by the fuzz suite:
/// `tests/fuzz/crashes/mcap/`).
pub fn record_length_limit(file_len: u64) -> usize {
    let l = file_len.saturating_mul(256).clamp(64 << 20, 1 << 30);
    usize::try_from(l).unwrap_or(1 << 30)
}

/// An MCAP message reader over `file` that counts the bytes read into `count`.
fn message_reader(
    file: std::fs::File,
    count: &std::rc::Rc<std::cell::Cell<u64>>,
) -> mcap::io::MessageReader<Counting<BufReader<std::fs::File>>> {
    let len = file.metadata().map(|m| m.len()).unwrap_or(u64::MAX);
    let options = mcap::sans_io::LinearReaderOptions::default().with_record_length_limit(record_length_limit(len));
    mcap::io::MessageReader::new_with_options(Counting { inner: BufReader::new(file), count: count.clone() }, options)
}

mod read;
pub use read::BagMessages;

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("xsurf-bag-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn write_then_read_back() {
        let dir = tmp("rt");
        let mut w = BagWriter::create(&dir, BagOptions { zstd: true }).unwrap();
        w.add_topic("/a", "std_msgs/msg/String", "string data\n", &Qos::RELIABLE).unwrap();
        w.add_topic("/tf_static", "std_msgs/msg/String", "string data\n", &Qos::STATIC).unwrap();
        for i in 0..10u64 {
            w.write("/a", 1000 + i, 1000 + i, &[0, 1, 0, 0, 1, 0, 0, 0, i as u8, 0]).unwrap();
        }
        w.write("/tf_static", 999, 999, &[0, 1, 0, 0, 1, 0, 0, 0, 0, 0]).unwrap();
        assert!(matches!(w.write("/b", 1, 1, &[]), Err(BagError::UnknownTopic(_))));
        let meta = w.finish().unwrap();
        assert_eq!(meta.message_count, 11);
        let bag = Bag::open(&dir).unwrap();
        assert_eq!(bag.metadata, meta);
        assert_eq!(bag.metadata.topics[1].qos, Some(Qos::STATIC));
        let msgs: Vec<_> = bag.messages().collect::<Result<_, _>>().unwrap();
        assert_eq!(msgs.len(), 11);
        assert_eq!(msgs[3].data[8], 3);
        assert!(bag.info().contains("Topic: /a"));
        assert!(matches!(BagWriter::create(&dir, BagOptions::default()), Err(BagError::Exists(_))));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn truncated_mcap_reads_up_to_the_cut_and_names_the_offset() {
        let dir = tmp("cut");
        let mut w = BagWriter::create(&dir, BagOptions::default()).unwrap();
        w.add_topic("/a", "std_msgs/msg/String", "string data\n", &Qos::RELIABLE).unwrap();
        for i in 0..2000u64 {
            w.write("/a", i, i, &[0u8; 64]).unwrap();
        }
        let meta = w.finish().unwrap();
        let file = dir.join(&meta.files[0]);
        let len = std::fs::metadata(&file).unwrap().len();
        let f = std::fs::OpenOptions::new().write(true).open(&file).unwrap();
        f.set_len(len * 2 / 3).unwrap();
        let bag = Bag::open(&dir).unwrap();
        let (ok, err) = both_readers(&bag);
        let e = err.expect("truncation reported");
        assert!(e.contains("MCAP error at byte offset") && !e.contains("byte offset 0:"), "{e}");
        assert!(!ok.is_empty() && ok.len() < 2000, "read {}", ok.len());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The messages of `bag` read by the threads and on this thread: the same, in the same
    /// order, ending with the same error (if any).
    fn both_readers(bag: &Bag) -> (Vec<RawMessage>, Option<String>) {
        let read = |it: BagMessages| {
            let (mut ok, mut err) = (Vec::new(), None);
            for m in it {
                match m {
                    Ok(m) => ok.push(m),
                    Err(e) => err = Some(e.to_string()),
                }
            }
            (ok, err)
        };
        let (threads, here) = (read(bag.messages()), read(bag.messages_here()));
        assert_eq!(threads.0.len(), here.0.len());
        for (a, b) in threads.0.iter().zip(&here.0) {
            assert_eq!(
                (&a.topic, &a.type_name, a.log_time_ns, &a.data),
                (&b.topic, &b.type_name, b.log_time_ns, &b.data)
            );
        }
        assert_eq!(threads.1, here.1);
        threads
    }

    #[test]
    fn chunks_decompressed_ahead_give_one_threads_messages_and_errors() {
        let dir = tmp("ahead");
        let mut w = BagWriter::create(&dir, BagOptions { zstd: true }).unwrap();
        w.add_topic("/a", "std_msgs/msg/String", "string data\n", &Qos::RELIABLE).unwrap();
        w.add_topic("/b", "std_msgs/msg/String", "string data\n", &Qos::RELIABLE).unwrap();
        // Messages of 100 kB: many chunks, each compressed.
        for i in 0..200u64 {
            let data: Vec<u8> = (0..100_000u64).map(|k| ((k * (i + 1)) % 251) as u8).collect();
            w.write(if i % 3 == 0 { "/b" } else { "/a" }, i, i, &data).unwrap();
        }
        let meta = w.finish().unwrap();
        let bag = Bag::open(&dir).unwrap();
        let (msgs, err) = both_readers(&bag);
        assert_eq!((msgs.len(), err), (200, None));
        assert!(msgs.iter().enumerate().all(|(i, m)| m.log_time_ns == i as u64 && m.data[1] == ((i + 1) % 251) as u8));
        // A damaged byte in the middle of the file: a chunk fails its decompression or its CRC;
        // the messages before it are read, the error names the file and an offset.
        let file = dir.join(&meta.files[0]);
        let mut bytes = std::fs::read(&file).unwrap();
        let at = bytes.len() / 2;
        bytes[at] ^= 0x5a;
        bytes[at + 1] ^= 0xa5;
        std::fs::write(&file, &bytes).unwrap();
        let (msgs, err) = both_readers(&bag);
        let err = err.expect("the damage is reported");
        assert!(err.contains(&meta.files[0]) && err.contains("byte offset"), "{err}");
        assert!(msgs.len() > 50 && msgs.len() < 200, "{} messages before the damage", msgs.len());
        // A chunk claiming more than a record may hold is refused, not allocated: the first
        // chunk's uncompressed size (its body's third field) made 2^62.
        bytes[at] ^= 0x5a;
        bytes[at + 1] ^= 0xa5;
        let mut pos = 8;
        while bytes[pos] != 0x06 {
            pos += 9 + u64::from_le_bytes(bytes[pos + 1..pos + 9].try_into().unwrap()) as usize;
        }
        bytes[pos + 9 + 16..pos + 9 + 24].copy_from_slice(&(1u64 << 62).to_le_bytes());
        std::fs::write(&file, &bytes).unwrap();
        let (msgs, err) = both_readers(&bag);
        let err = err.expect("the size is refused");
        assert!(err.contains("a chunk says it holds 4611686018427387904 bytes"), "{err}");
        assert!(msgs.is_empty());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn metadata_errors_name_the_file() {
        let p = Path::new("/x/metadata.yaml");
        assert!(matches!(BagMetadata::parse("nope: 1", p), Err(BagError::Metadata { .. })));
        assert!(matches!(BagMetadata::parse("{{{", p), Err(BagError::Metadata { .. })));
        let v9 = "rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: mcap\n  duration: {nanoseconds: 5}\n  starting_time: {nanoseconds_since_epoch: 7}\n  message_count: 1\n  topics_with_message_count:\n    - topic_metadata: {name: /t, type: std_msgs/msg/String, serialization_format: cdr, offered_qos_profiles: [{history: keep_last, depth: 3, reliability: best_effort, durability: volatile}]}\n      message_count: 1\n  relative_file_paths: [a_0.mcap]\n";
        let m = BagMetadata::parse(v9, p).unwrap();
        assert_eq!(m.topics[0].qos, Some(Qos { reliable: false, transient_local: false, depth: 3 }));
        let sqlite = v9.replace("storage_identifier: mcap", "storage_identifier: sqlite3");
        assert!(matches!(BagMetadata::parse(&sqlite, p), Err(BagError::Unsupported { .. })));
        assert!(matches!(Bag::open(Path::new("/nonexistent-bag")), Err(BagError::Metadata { .. })));
    }
}
