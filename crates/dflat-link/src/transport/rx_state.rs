//! The receive side's state of a [`Transport`](super::Transport): a
//! scratch buffer, dflat-link's stream parser, and a mirror of the
//! parser's unconsumed bytes (to tap frames byte-exactly).

use std::collections::VecDeque;

use super::*;

/// Receive side state: a scratch buffer, the stream parser and a mirror of
/// the parser's unconsumed bytes (to tap frames byte-exactly).
pub(super) struct RxState {
    pub(super) buf: Vec<u8>,
    pub(super) parser: FrameParser,
    pub(super) mirror: Vec<u8>,
    pub(super) pending: VecDeque<RecvEvent>,
}

impl RxState {
    pub(super) fn new(buf_len: usize) -> Self {
        Self {
            buf: vec![0; buf_len],
            parser: FrameParser::new(),
            mirror: Vec::with_capacity(4 * MAX_FRAME_LEN),
            pending: VecDeque::with_capacity(16),
        }
    }

    /// Feeds `len` bytes of `self.buf` to the parser and queues the events.
    /// `complete`: the bytes are a whole datagram (no frame continues).
    pub(super) fn ingest(
        &mut self,
        len: usize,
        complete: bool,
        arrival: Instant,
        from: Option<SocketAddr>,
        tap: Option<&TlogTap>,
    ) {
        let bytes = &self.buf[..len];
        // Keep the mirror equal to the parser's buffer after `push`.
        let keep = self.parser.pending();
        let drop_n = self.mirror.len().saturating_sub(keep);
        self.mirror.drain(..drop_n);
        self.mirror.extend_from_slice(bytes);
        let skipped_before = self.parser.skipped_bytes();
        let errors_before = self.errors_queued();
        self.parser.push(bytes);
        let ts = unix_time_us();
        let received = |frame: crate::frame::Frame| {
            RecvEvent::Frame(Box::new(Received {
                header: frame.header,
                message: frame.message,
                arrival,
                signed: frame.signed,
                from,
            }))
        };
        while let Some(item) = self.parser.next_frame() {
            match item {
                Ok(frame) => {
                    if let Some(tap) = tap.filter(|t| t.inbound) {
                        let end = self.mirror.len().saturating_sub(self.parser.pending());
                        match self.mirror.get(end.saturating_sub(frame.len)..end) {
                            Some(raw) if raw.len() == frame.len => tap.record(ts, raw),
                            _ => tap.record_message(ts, &frame.header, &frame.message),
                        }
                    }
                    self.pending.push_back(received(frame));
                }
                Err(e) => self.pending.push_back(RecvEvent::Error(e)),
            }
        }
        let skipped = self.parser.skipped_bytes() > skipped_before;
        if complete {
            // `finish` also resets the parser's counters.
            for item in self.parser.finish() {
                match item {
                    Ok(frame) => {
                        if let Some(tap) = tap.filter(|t| t.inbound) {
                            tap.record_message(ts, &frame.header, &frame.message);
                        }
                        self.pending.push_back(received(frame));
                    }
                    Err(e) => self.pending.push_back(RecvEvent::Error(e)),
                }
            }
            self.mirror.clear();
        }
        // Bytes outside any frame candidate: one error per chunk, unless a
        // bad candidate in this chunk already explains them.
        if skipped && self.errors_queued() == errors_before {
            self.pending
                .push_back(RecvEvent::Error(FrameError::NoMarker));
        }
    }

    /// Forgets a partial frame (the stream was reconnected).
    pub(super) fn reset_stream(&mut self) {
        self.parser = FrameParser::new();
        self.mirror.clear();
    }

    pub(super) fn errors_queued(&self) -> usize {
        self.pending
            .iter()
            .filter(|e| matches!(e, RecvEvent::Error(_)))
            .count()
    }
}
