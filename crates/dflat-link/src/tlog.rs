//! Telemetry logs (`.tlog`) as QGroundControl and MAVProxy write them: each
//! raw MAVLink frame prefixed by its receive/send time as an 8-byte
//! big-endian count of microseconds since the UNIX epoch. pymavlink's
//! `mavutil.mavlink_connection("x.tlog")` reads them.
//!
//! The writer takes already-serialized frames and a timestamp: the caller
//! owns the clock.

use std::io::{self, Read, Write};

use mavlink::dialects::common::MavMessage;
use mavlink::{MAV_STX, MAV_STX_V2, MavHeader};
use thiserror::Error;

use crate::frame::{Frame, parse_frame, serialize_v2};
use crate::{FrameError, LinkError};

/// Why a tlog could not be written or read.
#[derive(Debug, Error)]
pub enum TlogError {
    /// The underlying reader or writer failed.
    #[error("tlog I/O: {0}")]
    Io(#[from] io::Error),
    /// The bytes handed to the writer are not one MAVLink frame.
    #[error("not a single MAVLink frame ({len} bytes)")]
    NotAFrame {
        /// Length of the rejected byte slice.
        len: usize,
    },
    /// A record does not start with a MAVLink start marker.
    #[error("record at byte {offset}: byte {byte:#04x} is not a MAVLink start marker")]
    BadMarker {
        /// Offset of the record's frame in the file.
        offset: u64,
        /// The byte found.
        byte: u8,
    },
    /// The file ends inside a record.
    #[error("record at byte {offset} is truncated")]
    Truncated {
        /// Offset of the record in the file.
        offset: u64,
    },
}

/// Total length of the frame whose first 3 bytes are `head`, if it is one.
fn frame_len(head: [u8; 3]) -> Option<usize> {
    let payload = usize::from(head[1]);
    match head[0] {
        MAV_STX_V2 => {
            let signature = if head[2] & 0x01 != 0 { 13 } else { 0 };
            Some(10 + payload + 2 + signature)
        }
        MAV_STX => Some(6 + payload + 2),
        _ => None,
    }
}

/// Encodes one `.tlog` record — `timestamp_us` \[µs since the UNIX epoch\]
/// big-endian, then `frame` (exactly one MAVLink 1 or 2 frame) — into
/// `out`; returns its length. Lets a writer put a record on disk with one
/// `write` call.
pub fn encode_record(timestamp_us: u64, frame: &[u8], out: &mut [u8]) -> Result<usize, TlogError> {
    let head = match frame {
        [a, b, c, ..] => [*a, *b, *c],
        _ => return Err(TlogError::NotAFrame { len: frame.len() }),
    };
    let n = 8 + frame.len();
    if frame_len(head) != Some(frame.len()) || out.len() < n {
        return Err(TlogError::NotAFrame { len: frame.len() });
    }
    out[..8].copy_from_slice(&timestamp_us.to_be_bytes());
    out[8..n].copy_from_slice(frame);
    Ok(n)
}

/// Writes `.tlog` records to `W`.
#[derive(Debug)]
pub struct TlogWriter<W: Write> {
    inner: W,
    records: u64,
}

impl<W: Write> TlogWriter<W> {
    /// Wraps a writer (wrap a file in `BufWriter`).
    pub fn new(inner: W) -> Self {
        Self { inner, records: 0 }
    }

    /// Writes one record: `timestamp_us` \[µs since the UNIX epoch\] and one
    /// complete serialized frame (MAVLink 1 or 2, as sent or received).
    pub fn write_frame(&mut self, timestamp_us: u64, frame: &[u8]) -> Result<(), TlogError> {
        let head = match frame {
            [a, b, c, ..] => [*a, *b, *c],
            _ => return Err(TlogError::NotAFrame { len: frame.len() }),
        };
        if frame_len(head) != Some(frame.len()) {
            return Err(TlogError::NotAFrame { len: frame.len() });
        }
        self.inner.write_all(&timestamp_us.to_be_bytes())?;
        self.inner.write_all(frame)?;
        self.records += 1;
        Ok(())
    }

    /// Serializes `msg` as MAVLink 2 with `header` and writes it as one record.
    pub fn write_message(
        &mut self,
        timestamp_us: u64,
        header: &MavHeader,
        msg: &MavMessage,
    ) -> Result<(), LinkError> {
        let frame = serialize_v2(header, msg)?;
        self.write_frame(timestamp_us, frame.as_bytes())
            .map_err(|e| match e {
                TlogError::Io(io) => LinkError::Io(io),
                other => LinkError::Io(io::Error::other(other.to_string())),
            })
    }

    /// Records written so far.
    pub fn records(&self) -> u64 {
        self.records
    }

    /// Flushes the underlying writer.
    pub fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }

    /// Returns the underlying writer.
    pub fn into_inner(self) -> W {
        self.inner
    }
}

/// One `.tlog` record.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TlogRecord {
    /// Timestamp \[µs since the UNIX epoch\].
    pub timestamp_us: u64,
    /// The raw frame bytes.
    pub frame: Vec<u8>,
}

impl TlogRecord {
    /// Parses the frame (CRC checked).
    pub fn parse(&self) -> Result<Frame, FrameError> {
        parse_frame(&self.frame)
    }
}

/// Reads `.tlog` records from `R`. Yields `Err` once on a malformed record,
/// then stops.
#[derive(Debug)]
pub struct TlogReader<R: Read> {
    inner: R,
    offset: u64,
    done: bool,
}

impl<R: Read> TlogReader<R> {
    /// Wraps a reader (wrap a file in `BufReader`).
    pub fn new(inner: R) -> Self {
        Self {
            inner,
            offset: 0,
            done: false,
        }
    }

    /// Fills `buf` completely; `Ok(false)` on a clean EOF before any byte.
    fn fill(&mut self, buf: &mut [u8], at_record_start: bool) -> Result<bool, TlogError> {
        let mut got = 0;
        while got < buf.len() {
            match self.inner.read(&mut buf[got..]) {
                Ok(0) if got == 0 && at_record_start => return Ok(false),
                Ok(0) => {
                    return Err(TlogError::Truncated {
                        offset: self.offset,
                    });
                }
                Ok(n) => got += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e.into()),
            }
        }
        Ok(true)
    }

    fn read_record(&mut self) -> Result<Option<TlogRecord>, TlogError> {
        let mut ts = [0u8; 8];
        if !self.fill(&mut ts, true)? {
            return Ok(None);
        }
        let mut head = [0u8; 3];
        self.fill(&mut head, false)?;
        let Some(len) = frame_len(head) else {
            return Err(TlogError::BadMarker {
                offset: self.offset + 8,
                byte: head[0],
            });
        };
        let mut frame = vec![0u8; len];
        frame[..3].copy_from_slice(&head);
        self.fill(&mut frame[3..], false)?;
        self.offset += 8 + len as u64;
        Ok(Some(TlogRecord {
            timestamp_us: u64::from_be_bytes(ts),
            frame,
        }))
    }
}

impl<R: Read> Iterator for TlogReader<R> {
    type Item = Result<TlogRecord, TlogError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        match self.read_record() {
            Ok(Some(record)) => Some(Ok(record)),
            Ok(None) => {
                self.done = true;
                None
            }
            Err(e) => {
                self.done = true;
                Some(Err(e))
            }
        }
    }
}
