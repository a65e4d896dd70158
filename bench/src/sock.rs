//! Datagram-socket transports: Unix domain sockets (abstract namespace, so no files) and UDP on
//! 127.0.0.1. The plant learns each agent's address from its HELLO datagram.

use super::link::{Link, Msg, Wait, BLOCK_SLICE, HELLO, MAX_PAYLOAD};
use std::io;
use std::net::{SocketAddr, UdpSocket};
use std::os::fd::AsRawFd;
use std::os::linux::net::SocketAddrExt;
use std::os::unix::net::{SocketAddr as UnixAddr, UnixDatagram};
use std::time::Duration;

/// What both socket kinds offer.
pub trait Dgram: AsRawFd {
    /// Peer address type.
    type Addr: Clone;
    /// `sendto`.
    fn send_to_addr(&self, buf: &[u8], to: &Self::Addr) -> io::Result<usize>;
    /// `recvfrom`.
    fn recv_from_addr(&self, buf: &mut [u8]) -> io::Result<(usize, Self::Addr)>;
    /// Blocking mode on or off.
    fn nonblocking(&self, on: bool) -> io::Result<()>;
    /// Timeout of blocking receives.
    fn read_timeout(&self, t: Duration) -> io::Result<()>;
}

impl Dgram for UnixDatagram {
    type Addr = UnixAddr;
    fn send_to_addr(&self, buf: &[u8], to: &UnixAddr) -> io::Result<usize> {
        UnixDatagram::send_to_addr(self, buf, to)
    }
    fn recv_from_addr(&self, buf: &mut [u8]) -> io::Result<(usize, UnixAddr)> {
        self.recv_from(buf)
    }
    fn nonblocking(&self, on: bool) -> io::Result<()> {
        self.set_nonblocking(on)
    }
    fn read_timeout(&self, t: Duration) -> io::Result<()> {
        self.set_read_timeout(Some(t))
    }
}

impl Dgram for UdpSocket {
    type Addr = SocketAddr;
    fn send_to_addr(&self, buf: &[u8], to: &SocketAddr) -> io::Result<usize> {
        self.send_to(buf, to)
    }
    fn recv_from_addr(&self, buf: &mut [u8]) -> io::Result<(usize, SocketAddr)> {
        self.recv_from(buf)
    }
    fn nonblocking(&self, on: bool) -> io::Result<()> {
        self.set_nonblocking(on)
    }
    fn read_timeout(&self, t: Duration) -> io::Result<()> {
        self.set_read_timeout(Some(t))
    }
}

/// Abstract Unix socket address of the plant (`me == None`) or of agent `me` in case `case`.
pub fn uds_addr(prefix: &str, case: usize, me: Option<usize>) -> io::Result<UnixAddr> {
    let name = match me {
        None => format!("{prefix}c{case}plant"),
        Some(i) => format!("{prefix}c{case}a{i}"),
    };
    UnixAddr::from_abstract_name(name.as_bytes())
}

/// Binds a Unix datagram socket at an abstract address.
pub fn bind_uds(addr: &UnixAddr) -> io::Result<UnixDatagram> {
    UnixDatagram::bind_addr(addr)
}

/// Binds a UDP socket on 127.0.0.1 (port 0: any free port).
pub fn bind_udp(port: u16) -> io::Result<UdpSocket> {
    UdpSocket::bind(("127.0.0.1", port))
}

/// One end of a socket case. The plant sends to every known agent; an agent sends to the plant.
pub struct SockLink<S: Dgram> {
    sock: S,
    /// Plant: agents' addresses by index (filled by their HELLO). Agent: the plant's address.
    peers: Vec<Option<S::Addr>>,
    is_plant: bool,
    from: u32,
    polled: bool,
    out: Vec<u8>,
    inbuf: Vec<u8>,
}

impl<S: Dgram> SockLink<S> {
    /// Plant end for `n` agents.
    pub fn plant(sock: S, n: usize, payload: usize, wait: Wait) -> io::Result<Self> {
        Self::new(sock, vec![None; n], true, u32::MAX, payload, wait)
    }

    /// Agent `index`'s end, sending to `plant`.
    pub fn agent(
        sock: S,
        plant: S::Addr,
        index: u32,
        payload: usize,
        wait: Wait,
    ) -> io::Result<Self> {
        Self::new(sock, vec![Some(plant)], false, index, payload, wait)
    }

    fn new(
        sock: S,
        peers: Vec<Option<S::Addr>>,
        is_plant: bool,
        from: u32,
        payload: usize,
        wait: Wait,
    ) -> io::Result<Self> {
        // Block: plain blocking recv (one syscall). Spin/busy: non-blocking recv, poll(2) to block.
        let polled = wait != Wait::Block;
        sock.nonblocking(polled)?;
        if !polled {
            sock.read_timeout(BLOCK_SLICE)?;
        }
        Ok(SockLink {
            sock,
            peers,
            is_plant,
            from,
            polled,
            out: vec![0u8; payload],
            // Whatever the other side sends fits (the two directions may differ in size).
            inbuf: vec![0u8; MAX_PAYLOAD],
        })
    }

    fn read(&mut self) -> io::Result<Option<Msg>> {
        match self.sock.recv_from_addr(&mut self.inbuf) {
            Ok((len, addr)) => {
                let Some(m) = Msg::decode(&self.inbuf[..len]) else {
                    return Ok(None);
                };
                if self.is_plant && m.seq == HELLO {
                    if let Some(slot) = self.peers.get_mut(m.from as usize) {
                        *slot = Some(addr);
                    }
                }
                Ok(Some(m))
            }
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock
                        | io::ErrorKind::TimedOut
                        | io::ErrorKind::Interrupted
                ) =>
            {
                Ok(None)
            }
            Err(e) => Err(e),
        }
    }
}

impl<S: Dgram> Link for SockLink<S> {
    fn send(&mut self, seq: u64) -> io::Result<()> {
        Msg {
            seq,
            from: self.from,
        }
        .encode(&mut self.out);
        for (i, p) in self.peers.iter().enumerate() {
            let Some(addr) = p else {
                return Err(io::Error::other(format!("no address for peer {i}")));
            };
            self.sock.send_to_addr(&self.out, addr)?;
        }
        Ok(())
    }

    fn try_recv(&mut self) -> io::Result<Option<Msg>> {
        if self.polled {
            self.read()
        } else {
            Ok(None)
        }
    }

    fn block_recv(&mut self, timeout: Duration) -> io::Result<Option<Msg>> {
        if !self.polled {
            return self.read();
        }
        let mut pfd = libc::pollfd {
            fd: self.sock.as_raw_fd(),
            events: libc::POLLIN,
            revents: 0,
        };
        let ms = timeout.as_millis().clamp(1, i32::MAX as u128) as i32;
        // SAFETY: one valid pollfd for the duration of the call.
        let r = unsafe { libc::poll(&mut pfd, 1, ms) };
        if r < 0 {
            let e = io::Error::last_os_error();
            return if e.kind() == io::ErrorKind::Interrupted {
                Ok(None)
            } else {
                Err(e)
            };
        }
        self.read()
    }
}
