//! Why the SITL could not start or finish.

use std::net::SocketAddr;
use std::path::PathBuf;

use thiserror::Error;

/// Why the SITL could not start or finish.
#[derive(Debug, Error)]
pub enum SitlError {
    /// The connection string is not `udpin:HOST:PORT`.
    #[error("{what}: `{url}` is not a SITL endpoint (the SITL listens: udpin:HOST:PORT)")]
    Endpoint {
        /// Which endpoint (`link` or `gcs`).
        what: &'static str,
        /// The string given.
        url: String,
    },
    /// A socket could not be bound or configured.
    #[error("{what}: cannot listen on {addr}: {source}")]
    Bind {
        /// Which endpoint.
        what: &'static str,
        /// The address.
        addr: SocketAddr,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The plant options were refused by the lab.
    #[error("sitl plant: {0}")]
    Plant(#[from] dflat_sim::SimError),
    /// The truth CSV could not be created or written.
    #[error("truth CSV {file}: {source}")]
    Truth {
        /// The file.
        file: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A SITL thread could not be started.
    #[error("cannot start the {0} thread: {1}")]
    Thread(&'static str, std::io::Error),
    /// A SITL thread panicked (a bug).
    #[error("the SITL {0} thread panicked")]
    Panicked(&'static str),
    /// `sitl.signing_key_file` is refused (mode, owner, contents).
    #[error("sitl.signing_key_file = {file}: {reason}")]
    SigningKey {
        /// The key file.
        file: PathBuf,
        /// Why, in words.
        reason: String,
    },
}
