//! [`Endpoint`]: a parsed connection string of the mavlink crate's syntax.

use std::fmt;
use std::str::FromStr;

use super::TransportError;

/// A parsed MAVLink connection string.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Endpoint {
    /// `udpin:HOST:PORT` — bind and reply to the last sender.
    UdpIn {
        /// Host name or address to bind (e.g. `0.0.0.0`, `127.0.0.1`).
        host: String,
        /// UDP port (0 = any free port, see [`Transport::local_addr`](super::Transport::local_addr)).
        port: u16,
    },
    /// `udpout:HOST:PORT` — send to the address and receive replies.
    UdpOut {
        /// Host name or address of the peer.
        host: String,
        /// UDP port of the peer.
        port: u16,
    },
    /// `tcpout:HOST:PORT` — connect to a TCP server.
    TcpOut {
        /// Host name or address of the server.
        host: String,
        /// TCP port of the server.
        port: u16,
    },
    /// `serial:PATH:BAUD` — a serial port, 8N1.
    Serial {
        /// Device path, e.g. `/dev/ttyTHS2`.
        path: String,
        /// Baud rate \[bit/s\].
        baud: u32,
    },
}

impl Endpoint {
    /// Parses a connection string (see the variants). IPv6 hosts may be
    /// written in brackets: `udpout:[::1]:14540`.
    pub fn parse(url: &str) -> Result<Self, TransportError> {
        let bad = |reason: &str| TransportError::BadUrl {
            url: url.to_owned(),
            reason: format!(
                "{reason}; expected udpin:HOST:PORT, udpout:HOST:PORT, tcpout:HOST:PORT or serial:PATH:BAUD"
            ),
        };
        let url_trim = url.trim();
        let Some((scheme, rest)) = url_trim.split_once(':') else {
            return Err(bad("no `kind:` prefix"));
        };
        let Some((head, tail)) = rest.rsplit_once(':') else {
            return Err(bad("missing `:PORT` / `:BAUD`"));
        };
        if head.is_empty() {
            return Err(bad("empty host / path"));
        }
        let host = head
            .strip_prefix('[')
            .and_then(|h| h.strip_suffix(']'))
            .unwrap_or(head)
            .to_owned();
        let port = || {
            tail.parse::<u16>()
                .map_err(|_| bad(&format!("port `{tail}` is not an integer 0–65535")))
        };
        match scheme {
            "udpin" => Ok(Endpoint::UdpIn {
                host,
                port: port()?,
            }),
            "udpout" | "udp" => Ok(Endpoint::UdpOut {
                host,
                port: port()?,
            }),
            "tcpout" | "tcp" => Ok(Endpoint::TcpOut {
                host,
                port: port()?,
            }),
            "serial" => {
                let baud =
                    tail.parse::<u32>().ok().filter(|b| *b > 0).ok_or_else(|| {
                        bad(&format!("baud rate `{tail}` is not a positive integer"))
                    })?;
                Ok(Endpoint::Serial {
                    path: head.to_owned(),
                    baud,
                })
            }
            other => Err(bad(&format!("unknown kind `{other}`"))),
        }
    }

    fn host_port(host: &str, port: u16) -> String {
        if host.contains(':') {
            format!("[{host}]:{port}")
        } else {
            format!("{host}:{port}")
        }
    }
}

impl FromStr for Endpoint {
    type Err = TransportError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Endpoint::parse(s)
    }
}

impl fmt::Display for Endpoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Endpoint::UdpIn { host, port } => write!(f, "udpin:{}", Self::host_port(host, *port)),
            Endpoint::UdpOut { host, port } => {
                write!(f, "udpout:{}", Self::host_port(host, *port))
            }
            Endpoint::TcpOut { host, port } => {
                write!(f, "tcpout:{}", Self::host_port(host, *port))
            }
            Endpoint::Serial { path, baud } => write!(f, "serial:{path}:{baud}"),
        }
    }
}
