//! The names of the SITL's two links, shared by its pure step, the state
//! of its PX4 face and the I/O around them.

/// One of the SITL's two links.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Link {
    /// The vehicle link (the daemon).
    Vehicle,
    /// The ground-station port.
    Gcs,
}
