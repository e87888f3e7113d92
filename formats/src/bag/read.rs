//! A bag's messages in file order, its chunks decompressed ahead on worker threads.
//!
//! One thread reads the storage files and cuts them into pieces: the records outside chunks,
//! and each chunk as stored. Each chunk is decompressed (and its CRC checked) by one of the
//! workers, while the next ones are read and the caller handles the messages of the earlier
//! ones. The caller takes the pieces in file order, whichever worker finishes first, so the
//! messages are those, in the order, of one thread reading the files. Where no thread can be
//! started, the caller reads and decompresses each piece itself.

use super::{mcap_err, record_length_limit, BagError, RawMessage};
use crate::FileError;
use mcap::read::ChannelAccumulator;
use mcap::records::{op, Record};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use std::collections::VecDeque;
use std::io::{BufReader, Read};
use std::path::PathBuf;
use std::sync::mpsc::{channel, sync_channel, Receiver, Sender};
use std::sync::{Arc, Mutex, PoisonError};

/// Chunks read ahead of the caller: the bound on the memory of chunks waiting (a chunk of our
/// bags holds at most one or two images).
const AHEAD: usize = 8;

/// What the reading thread cuts a storage file into, in file order.
enum Piece {
    /// A storage file begins: its channel and schema ids are its own.
    File(PathBuf),
    /// A schema, channel or message record outside chunks, and the file's bytes read up to it.
    Record(Record<'static>, u64),
    /// A chunk as stored.
    Chunk(Chunk),
    /// The file cannot be read further: the bag's messages end here.
    Failed(BagError),
}

/// A chunk as stored in a storage file.
struct Chunk {
    path: PathBuf,
    /// The chunk record's body (after its opcode and length).
    body: Vec<u8>,
    /// The file's bytes read up to the chunk's end.
    offset: u64,
    /// The longest record (or decompressed chunk) of the file ([`record_length_limit`]).
    limit: u64,
}

/// A piece as the caller takes it: records ready, or a chunk's records still being made; each
/// with the file's bytes read up to it.
enum Ready {
    File(PathBuf),
    Records(Result<Vec<Record<'static>>, BagError>, u64),
    Pending(Receiver<Result<Vec<Record<'static>>, BagError>>, u64),
}

impl Ready {
    /// A piece read on this thread, its chunk (if it is one) decompressed here.
    fn here(piece: Piece) -> Ready {
        match piece {
            Piece::File(path) => Ready::File(path),
            Piece::Record(r, at) => Ready::Records(Ok(vec![r]), at),
            Piece::Chunk(c) => {
                let at = c.offset;
                Ready::Records(unpack(c), at)
            }
            Piece::Failed(e) => Ready::Records(Err(e), 0),
        }
    }
}

/// Reads one storage file after the other into [`Piece`]s.
struct Storage {
    files: VecDeque<PathBuf>,
    current: Option<Scan>,
    failed: bool,
}

/// One storage file being read.
struct Scan {
    path: PathBuf,
    file: BufReader<std::fs::File>,
    reader: LinearReader,
    /// Bytes read so far.
    read: u64,
    /// Past the data end record: the summary repeats what was read, and is not looked at.
    past_data_end: bool,
    /// [`record_length_limit`] of the file.
    limit: u64,
    /// Where the next record starts (after the 8 bytes of magic at first).
    next_record: u64,
    /// What was saved of a record cut short (see [`salvage`]), to be handed out first.
    salvaged: VecDeque<Piece>,
}

impl Storage {
    fn next_piece(&mut self) -> Option<Piece> {
        loop {
            if self.failed {
                return None;
            }
            let Some(scan) = self.current.as_mut() else {
                let path = self.files.pop_front()?;
                match std::fs::File::open(&path) {
                    Ok(file) => {
                        let limit = record_length_limit(file.metadata().map_or(u64::MAX, |m| m.len()));
                        let options =
                            LinearReaderOptions::default().with_emit_chunks(true).with_record_length_limit(limit);
                        let reader = LinearReader::new_with_options(options);
                        let (file, limit) = (BufReader::new(file), limit as u64);
                        self.current = Some(Scan {
                            path: path.clone(),
                            file,
                            reader,
                            read: 0,
                            past_data_end: false,
                            limit,
                            next_record: 8,
                            salvaged: VecDeque::new(),
                        });
                        return Some(Piece::File(path));
                    }
                    Err(e) => {
                        self.failed = true;
                        return Some(Piece::Failed(FileError::new(&path, e).into()));
                    }
                }
            };
            match scan.next_piece() {
                Some(Piece::Failed(e)) => {
                    self.failed = true;
                    return Some(Piece::Failed(e));
                }
                Some(piece) => return Some(piece),
                None => self.current = None,
            }
        }
    }
}

impl Scan {
    /// The next piece of this file; `None` at its end.
    fn next_piece(&mut self) -> Option<Piece> {
        if let Some(piece) = self.salvaged.pop_front() {
            return Some(piece);
        }
        loop {
            let event = match self.reader.next_event()? {
                Ok(event) => event,
                Err(e) => {
                    let failed = mcap_err(&self.path, self.read, e);
                    if self.past_data_end {
                        return Some(Piece::Failed(failed));
                    }
                    // A chunk cut short (a recording that did not finish) still holds the
                    // messages written before the cut.
                    let at = self.next_record;
                    self.salvaged = salvage(&self.path, at, self.limit).map(|r| Piece::Record(r, at)).collect();
                    self.salvaged.push_back(Piece::Failed(failed));
                    return self.salvaged.pop_front();
                }
            };
            if let LinearReadEvent::Record { data, .. } = &event {
                self.next_record += 9 + data.len() as u64;
            }
            match event {
                LinearReadEvent::ReadRequest(need) => match fill(&mut self.reader, need, &mut self.file) {
                    Ok(n) => self.read += n as u64,
                    Err(e) => return Some(Piece::Failed(FileError::new(&self.path, e).into())),
                },
                LinearReadEvent::Record { opcode: op::DATA_END, .. } => self.past_data_end = true,
                LinearReadEvent::Record { .. } if self.past_data_end => {}
                LinearReadEvent::Record { opcode, data } => match mcap::parse_record(opcode, data) {
                    // Refused before anything is allocated for it.
                    Ok(Record::Chunk { header, .. }) if header.uncompressed_size > self.limit => {
                        let n = header.uncompressed_size;
                        let e = format!("a chunk says it holds {n} bytes, more than a record may");
                        return Some(Piece::Failed(mcap_err(&self.path, self.read, e)));
                    }
                    Ok(Record::Chunk { .. }) => {
                        let (path, body, offset, limit) = (self.path.clone(), data.to_vec(), self.read, self.limit);
                        return Some(Piece::Chunk(Chunk { path, body, offset, limit }));
                    }
                    Ok(r) => {
                        if let Some(r) = message_part(r) {
                            return Some(Piece::Record(r, self.read));
                        }
                    }
                    Err(e) => return Some(Piece::Failed(mcap_err(&self.path, self.read, e))),
                },
            }
        }
    }
}

/// The schema, channel and message records that can be read from the record at `from` on, by
/// the streaming reader, which hands out a chunk's records as it decompresses them: what a
/// record cut short (a chunk whose end is missing) still holds. Nothing where the file cannot
/// be read again.
fn salvage(path: &std::path::Path, from: u64, limit: u64) -> impl Iterator<Item = Record<'static>> {
    use std::io::{Seek, SeekFrom};
    let file = std::fs::File::open(path).and_then(|mut f| f.seek(SeekFrom::Start(from)).map(|_| f)).ok();
    let options = LinearReaderOptions::default()
        .with_skip_start_magic(true)
        .with_record_length_limit(usize::try_from(limit).unwrap_or(usize::MAX));
    let mut reader = LinearReader::new_with_options(options);
    let mut file = file.map(BufReader::new);
    std::iter::from_fn(move || loop {
        let f = file.as_mut()?;
        match reader.next_event()? {
            Ok(LinearReadEvent::ReadRequest(need)) => {
                fill(&mut reader, need, f).ok()?;
            }
            Ok(LinearReadEvent::Record { opcode, data }) => {
                if let Some(r) = message_part(mcap::parse_record(opcode, data).ok()?) {
                    return Some(r);
                }
            }
            Err(_) => return None,
        }
    })
}

/// A chunk's records, decompressed and checked against its CRC, by the reader that reads the
/// files: handed the chunk record alone, with the file's limit on a record's length.
fn unpack(c: Chunk) -> Result<Vec<Record<'static>>, BagError> {
    let options = LinearReaderOptions::default()
        .with_skip_start_magic(true)
        .with_skip_end_magic(true)
        .with_validate_chunk_crcs(true)
        .with_record_length_limit(usize::try_from(c.limit).unwrap_or(usize::MAX));
    let mut reader = LinearReader::new_with_options(options);
    let mut head = [0u8; 9];
    head[0] = op::CHUNK;
    head[1..].copy_from_slice(&(c.body.len() as u64).to_le_bytes());
    let mut record = head.as_slice().chain(c.body.as_slice());
    let mut records = Vec::new();
    while let Some(event) = reader.next_event() {
        let bad = |e: mcap::McapError| mcap_err(&c.path, c.offset, format!("in the chunk ending here: {e}"));
        match event.map_err(bad)? {
            LinearReadEvent::ReadRequest(need) => {
                fill(&mut reader, need, &mut record).map_err(|e| mcap_err(&c.path, c.offset, e))?;
            }
            LinearReadEvent::Record { opcode, data } => {
                records.extend(message_part(mcap::parse_record(opcode, data).map_err(bad)?));
            }
        }
    }
    Ok(records)
}

/// Answers the reader's request for `need` bytes from `src` (retried where a signal
/// interrupts the read); the bytes read, none at the end.
fn fill(reader: &mut LinearReader, need: usize, src: &mut impl Read) -> std::io::Result<usize> {
    let n = loop {
        match src.read(reader.insert(need)) {
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            r => break r?,
        }
    };
    reader.notify_read(n);
    Ok(n)
}

/// The records the messages need (schemas, channels, messages), owned; `None` for the others.
fn message_part(r: Record<'_>) -> Option<Record<'static>> {
    matches!(r, Record::Schema { .. } | Record::Channel(_) | Record::Message { .. }).then(|| r.into_owned())
}

/// A chunk to decompress, and where its records go.
type Job = (Chunk, Sender<Result<Vec<Record<'static>>, BagError>>);

/// Where the pieces come from: a reading thread and its workers, or the caller itself.
enum Source {
    Threads(Receiver<Ready>),
    Here(Box<Storage>),
}

/// Iterator over a bag's messages, in file order. After an error (a truncated or corrupt
/// file) it ends; the messages before it have been returned.
pub struct BagMessages {
    source: Source,
    /// The storage file whose records are being handed out.
    path: PathBuf,
    /// Its schemas and channels so far.
    channels: ChannelAccumulator<'static>,
    /// Records of the current piece not yet looked at.
    records: VecDeque<Record<'static>>,
    /// The file's bytes read up to the current piece (for its errors).
    at: u64,
    failed: bool,
}

impl BagMessages {
    /// The messages of `files` (storage files, in order), decompressed by up to `workers`
    /// threads beside a reading thread (none: read here).
    pub(super) fn new(files: Vec<PathBuf>, workers: usize) -> BagMessages {
        let storage = Storage { files: files.into(), current: None, failed: false };
        BagMessages {
            source: if workers == 0 { Source::Here(Box::new(storage)) } else { start(storage, workers) },
            path: PathBuf::new(),
            channels: ChannelAccumulator::default(),
            records: VecDeque::new(),
            at: 0,
            failed: false,
        }
    }

    /// The next piece's records, in file order.
    fn next_records(&mut self) -> Option<Result<Vec<Record<'static>>, BagError>> {
        let ready = match &mut self.source {
            Source::Threads(rx) => rx.recv().ok()?,
            Source::Here(storage) => Ready::here(storage.next_piece()?),
        };
        match ready {
            Ready::File(path) => {
                self.path = path;
                self.channels = ChannelAccumulator::default();
                Some(Ok(Vec::new()))
            }
            Ready::Records(r, at) => {
                self.at = at;
                Some(r)
            }
            // A worker that has gone without an answer (it panicked) ends the bag there.
            Ready::Pending(rx, at) => {
                self.at = at;
                Some(rx.recv().unwrap_or_else(|_| {
                    Err(mcap_err(&self.path, at, "the thread decompressing a chunk stopped without a result"))
                }))
            }
        }
    }

    /// The message of record `r`, if it is one; schemas and channels are taken in.
    fn message(&mut self, r: Record<'static>) -> Result<Option<RawMessage>, BagError> {
        let bad = |e: mcap::McapError| mcap_err(&self.path, self.at, e);
        match r {
            Record::Schema { header, data } => self.channels.add_schema(header, data).map_err(bad).map(|()| None),
            Record::Channel(c) => self.channels.add_channel(c).map_err(bad).map(|()| None),
            Record::Message { header, data } => {
                let channel = self
                    .channels
                    .get(header.channel_id)
                    .ok_or_else(|| bad(mcap::McapError::UnknownChannel(header.sequence, header.channel_id)))?;
                Ok(Some(RawMessage {
                    topic: channel.topic.clone(),
                    type_name: channel.schema.as_ref().map(|s| s.name.clone()).unwrap_or_default(),
                    log_time_ns: header.log_time,
                    publish_time_ns: header.publish_time,
                    data: data.into_owned(),
                }))
            }
            _ => Ok(None),
        }
    }
}

impl Iterator for BagMessages {
    type Item = Result<RawMessage, BagError>;
    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if self.failed {
                return None;
            }
            let Some(r) = self.records.pop_front() else {
                match self.next_records()? {
                    Ok(records) => self.records = records.into(),
                    Err(e) => {
                        self.failed = true;
                        return Some(Err(e));
                    }
                }
                continue;
            };
            match self.message(r) {
                Ok(Some(m)) => return Some(Ok(m)),
                Ok(None) => {}
                Err(e) => {
                    self.failed = true;
                    return Some(Err(e));
                }
            }
        }
    }
}

/// Starts the reading thread and `workers` decompressing threads. They end when the caller
/// drops its end (a send fails) or the files are read. Where the reading thread cannot be
/// started, the caller reads; where no worker can, the reading thread decompresses.
fn start(storage: Storage, workers: usize) -> Source {
    let (jobs_tx, jobs_rx) = channel::<Job>();
    let jobs_rx = Arc::new(Mutex::new(jobs_rx));
    let mut started = 0;
    for i in 0..workers {
        let jobs = jobs_rx.clone();
        let spawned = std::thread::Builder::new().name(format!("xsurf-bag-unpack-{i}")).spawn(move || loop {
            let job = jobs.lock().unwrap_or_else(PoisonError::into_inner).recv();
            let Ok((chunk, tx)) = job else { return };
            // The caller may have stopped reading: nothing to do with the result then.
            let _ = tx.send(unpack(chunk));
        });
        started += usize::from(spawned.is_ok());
    }
    let (tx, rx) = sync_channel::<Ready>(AHEAD);
    // The reading thread owns the storage; if it cannot start, it comes back to be read here.
    let slot = Arc::new(Mutex::new(Some(storage)));
    let theirs = slot.clone();
    let reading = std::thread::Builder::new().name("xsurf-bag-read".into()).spawn(move || {
        let Some(mut storage) = theirs.lock().unwrap_or_else(PoisonError::into_inner).take() else { return };
        while let Some(piece) = storage.next_piece() {
            let ready = match piece {
                Piece::Chunk(c) if started > 0 => {
                    let (done_tx, done_rx) = channel();
                    let at = c.offset;
                    if jobs_tx.send((c, done_tx)).is_err() {
                        return;
                    }
                    Ready::Pending(done_rx, at)
                }
                piece => Ready::here(piece),
            };
            if tx.send(ready).is_err() {
                return;
            }
        }
    });
    match reading {
        Ok(_) => Source::Threads(rx),
        Err(_) => match slot.lock().unwrap_or_else(PoisonError::into_inner).take() {
            Some(storage) => Source::Here(Box::new(storage)),
            None => Source::Threads(rx),
        },
    }
}
