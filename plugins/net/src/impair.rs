//! A seeded impairment relay for real traffic: these machines have no `tc netem`, so tests
//! and `avatarm bench network` put this between the sites.
//!
//! - [`Relay::tcp`]: a TCP proxy. Each direction's bytes are held for the one-way delay plus a
//!   jitter drawn per chunk (order kept, as TCP keeps it), paced by a bandwidth cap, and held
//!   back entirely during a cut, then delivered. No loss: a TCP stream cannot lose bytes. Each
//!   direction holds at most [`Impairment::queue_bytes`] (delayed, queued behind the cap or held
//!   through a cut); when that is full the relay stops reading, so the sender's socket buffer
//!   fills and then its writes block, as behind a real slow or dead link.
//! - [`Relay::udp`]: a UDP forwarder. Each datagram is dropped with the loss probability or
//!   delayed by the delay plus jitter (datagrams may reorder, as on a real path); a cut drops
//!   everything.
//!
//! One seeded generator (SplitMix64) per direction: the same seed gives the same drops and
//! delays for the same traffic.

use std::collections::BinaryHeap;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream, UdpSocket};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, channel};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::NetError;

/// What the relay does to traffic, each direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Impairment {
    /// One-way delay (s).
    pub delay_s: f64,
    /// Jitter: each chunk or datagram gets an extra delay uniform in `0..jitter_s` (s).
    pub jitter_s: f64,
    /// Probability of dropping a datagram (UDP only; 0–1).
    pub loss: f64,
    /// Bandwidth cap (bits/s; `None`: none).
    pub bandwidth_bps: Option<f64>,
    /// Seed of the drops and jitter.
    pub seed: u64,
    /// What one TCP direction holds at most (bytes, ≥ 64 KiB): in flight through the delay,
    /// queued behind the cap, held through a cut. Default 4 MiB (Linux's largest autotuned
    /// socket buffer).
    pub queue_bytes: usize,
}

/// The smallest [`Impairment::queue_bytes`]: one read of the relay's.
pub const MIN_QUEUE_BYTES: usize = 64 * 1024;

impl Default for Impairment {
    fn default() -> Self {
        Self {
            delay_s: 0.0,
            jitter_s: 0.0,
            loss: 0.0,
            bandwidth_bps: None,
            seed: 1,
            queue_bytes: 4 << 20,
        }
    }
}

impl Impairment {
    /// Checks the numbers; the error names the field.
    pub fn validate(&self) -> Result<(), NetError> {
        if !(self.delay_s.is_finite() && (0.0..=60.0).contains(&self.delay_s)) {
            return Err(invalid(format!(
                "delay_s {} must be in 0..=60",
                self.delay_s
            )));
        }
        if !(self.jitter_s.is_finite() && (0.0..=60.0).contains(&self.jitter_s)) {
            return Err(invalid(format!(
                "jitter_s {} must be in 0..=60",
                self.jitter_s
            )));
        }
        if !(0.0..=1.0).contains(&self.loss) {
            return Err(invalid(format!("loss {} must be in 0..=1", self.loss)));
        }
        if let Some(b) = self.bandwidth_bps
            && !(b.is_finite() && b > 0.0)
        {
            return Err(invalid(format!("bandwidth_bps {b} must be > 0")));
        }
        if self.queue_bytes < MIN_QUEUE_BYTES {
            return Err(invalid(format!(
                "queue_bytes {} must be at least {MIN_QUEUE_BYTES}",
                self.queue_bytes
            )));
        }
        Ok(())
    }
}

/// An impairment setting out of range: [`NetError::Config`] naming the impairment.
fn invalid(message: String) -> NetError {
    NetError::Config {
        what: "impairment".to_owned(),
        message,
    }
}

/// SplitMix64: a small, well-known seeded generator.
#[derive(Debug, Clone)]
struct Rng(u64);

impl Rng {
    fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Counters of a relay (both directions).
#[derive(Debug, Default)]
pub struct RelayStats {
    /// Bytes forwarded.
    pub bytes: AtomicU64,
    /// Datagrams or chunks forwarded.
    pub packets: AtomicU64,
    /// Datagrams dropped (loss or cut).
    pub dropped: AtomicU64,
    /// The most bytes one TCP direction held at once.
    pub held_max: AtomicU64,
    /// Times a TCP direction stopped reading because it held [`Impairment::queue_bytes`].
    pub backpressure: AtomicU64,
}

struct Shared {
    impairment: Mutex<Impairment>,
    cut_until: Mutex<Option<Instant>>,
    stop: AtomicBool,
    stats: RelayStats,
}

impl Shared {
    fn new(impairment: Impairment) -> Arc<Self> {
        Arc::new(Self {
            impairment: Mutex::new(impairment),
            cut_until: Mutex::new(None),
            stop: AtomicBool::new(false),
            stats: RelayStats::default(),
        })
    }

    fn impairment(&self) -> Impairment {
        *self.impairment.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn cut_until(&self) -> Option<Instant> {
        self.cut_until
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .filter(|t| *t > Instant::now())
    }

    fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }
}

/// A running relay; stops when dropped.
pub struct Relay {
    addr: SocketAddr,
    shared: Arc<Shared>,
}

impl Relay {
    /// A TCP relay on 127.0.0.1 (a free port) to `upstream`.
    pub fn tcp(upstream: SocketAddr, impairment: Impairment) -> std::io::Result<Self> {
        impairment
            .validate()
            .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e))?;
        let listener = TcpListener::bind("127.0.0.1:0")?;
        let addr = listener.local_addr()?;
        listener.set_nonblocking(true)?;
        let shared = Shared::new(impairment);
        let s = shared.clone();
        std::thread::Builder::new()
            .name("relay accept".into())
            .spawn(move || {
                let mut connection = 0u64;
                while !s.stopped() {
                    match listener.accept() {
                        Ok((client, _)) => {
                            connection += 1;
                            let _ = client.set_nonblocking(false);
                            if let Ok(server) = TcpStream::connect(upstream) {
                                let _ = client.set_nodelay(true);
                                let _ = server.set_nodelay(true);
                                for (dir, (from, to)) in [
                                    (client.try_clone(), server.try_clone()),
                                    (server.try_clone(), client.try_clone()),
                                ]
                                .into_iter()
                                .enumerate()
                                {
                                    if let (Ok(from), Ok(to)) = (from, to) {
                                        let seed = connection * 2 + dir as u64;
                                        pump_tcp(from, to, s.clone(), seed);
                                    }
                                }
                            }
                        }
                        Err(_) => std::thread::sleep(Duration::from_millis(5)),
                    }
                }
            })?;
        Ok(Self { addr, shared })
    }

    /// A UDP relay on 127.0.0.1 (a free port) to `upstream`.
    pub fn udp(upstream: SocketAddr, impairment: Impairment) -> std::io::Result<Self> {
        impairment
            .validate()
            .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e))?;
        let front = UdpSocket::bind("127.0.0.1:0")?;
        let addr = front.local_addr()?;
        front.set_read_timeout(Some(Duration::from_millis(50)))?;
        let shared = Shared::new(impairment);
        let s = shared.clone();
        std::thread::Builder::new()
            .name("relay udp".into())
            .spawn(move || udp_front(front, upstream, s))?;
        Ok(Self { addr, shared })
    }

    /// Where clients connect.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Changes the impairment from now on, after checking it ([`Impairment::validate`]).
    pub fn set_checked(&self, impairment: Impairment) -> Result<(), NetError> {
        impairment.validate()?;
        self.set(impairment);
        Ok(())
    }

    /// Changes the impairment from now on (not checked: a test's or a bench's own settings).
    pub fn set(&self, impairment: Impairment) {
        *self
            .shared
            .impairment
            .lock()
            .unwrap_or_else(|e| e.into_inner()) = impairment;
    }

    /// Cuts the link for `duration` from now (TCP: held back; UDP: dropped).
    pub fn cut_for(&self, duration: Duration) {
        *self
            .shared
            .cut_until
            .lock()
            .unwrap_or_else(|e| e.into_inner()) = Some(Instant::now() + duration);
    }

    /// The counters.
    pub fn stats(&self) -> &RelayStats {
        &self.shared.stats
    }
}

impl Drop for Relay {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
    }
}

/// One TCP direction: a reader stamping chunks, a writer releasing them when due.
fn pump_tcp(mut from: TcpStream, mut to: TcpStream, shared: Arc<Shared>, seed: u64) {
    let (tx, rx) = channel::<(Instant, Vec<u8>)>();
    let reader_shared = shared.clone();
    // Bytes read and not yet written on; whether the writer has stopped.
    let held = Arc::new(AtomicU64::new(0));
    let reader_held = held.clone();
    let writer_done = Arc::new(AtomicBool::new(false));
    let reader_writer_done = writer_done.clone();
    let _ = std::thread::Builder::new()
        .name("relay read".into())
        .spawn(move || {
            let mut buf = vec![0u8; MIN_QUEUE_BYTES];
            let mut waiting = false;
            while !reader_shared.stopped() && !reader_writer_done.load(Ordering::Relaxed) {
                // Full: stop reading (the sender's socket buffer fills, then it blocks).
                let limit = reader_shared.impairment().queue_bytes.max(MIN_QUEUE_BYTES) as u64;
                if reader_held.load(Ordering::Relaxed) + buf.len() as u64 > limit {
                    if !waiting {
                        waiting = true;
                        reader_shared
                            .stats
                            .backpressure
                            .fetch_add(1, Ordering::Relaxed);
                    }
                    std::thread::sleep(Duration::from_millis(1));
                    continue;
                }
                waiting = false;
                match from.read(&mut buf) {
                    Ok(0) | Err(_) => break,
                    Ok(n) => {
                        let now_held =
                            reader_held.fetch_add(n as u64, Ordering::Relaxed) + n as u64;
                        reader_shared
                            .stats
                            .held_max
                            .fetch_max(now_held, Ordering::Relaxed);
                        if tx.send((Instant::now(), buf[..n].to_vec())).is_err() {
                            break;
                        }
                    }
                }
            }
        });
    let _ = std::thread::Builder::new()
        .name("relay write".into())
        .spawn(move || {
            let mut rng = Rng(shared.impairment().seed ^ seed.wrapping_mul(0x9E37_79B9));
            let mut last_due = Instant::now();
            while let Ok((arrived, chunk)) = rx.recv() {
                let imp = shared.impairment();
                let extra = imp.delay_s + imp.jitter_s * rng.next_f64();
                let mut due = (arrived + Duration::from_secs_f64(extra)).max(last_due);
                if let Some(bps) = imp.bandwidth_bps {
                    due =
                        due.max(last_due + Duration::from_secs_f64(chunk.len() as f64 * 8.0 / bps));
                }
                std::thread::sleep(due.saturating_duration_since(Instant::now()));
                while let Some(until) = shared.cut_until() {
                    std::thread::sleep(until.saturating_duration_since(Instant::now()));
                }
                last_due = due.max(Instant::now());
                if shared.stopped() || to.write_all(&chunk).is_err() {
                    let _ = to.shutdown(std::net::Shutdown::Both);
                    break;
                }
                held.fetch_sub(chunk.len() as u64, Ordering::Relaxed);
                shared
                    .stats
                    .bytes
                    .fetch_add(chunk.len() as u64, Ordering::Relaxed);
                shared.stats.packets.fetch_add(1, Ordering::Relaxed);
            }
            writer_done.store(true, Ordering::Relaxed);
            let _ = to.shutdown(std::net::Shutdown::Both);
        });
}

/// A datagram due at a time (the heap's order: earliest first).
struct Due {
    at: Instant,
    seq: u64,
    data: Vec<u8>,
}

impl PartialEq for Due {
    fn eq(&self, other: &Self) -> bool {
        (self.at, self.seq) == (other.at, other.seq)
    }
}
impl Eq for Due {}
impl PartialOrd for Due {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Due {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        (other.at, other.seq).cmp(&(self.at, self.seq))
    }
}

/// Decides a datagram's fate: `None` dropped, else when it is due.
fn schedule(shared: &Shared, rng: &mut Rng, len: usize, last: &mut Instant) -> Option<Instant> {
    let imp = shared.impairment();
    let lost = rng.next_f64() < imp.loss;
    let jitter = imp.jitter_s * rng.next_f64();
    if lost || shared.cut_until().is_some() {
        shared.stats.dropped.fetch_add(1, Ordering::Relaxed);
        return None;
    }
    let mut due = Instant::now() + Duration::from_secs_f64(imp.delay_s + jitter);
    if let Some(bps) = imp.bandwidth_bps {
        due = due.max(*last + Duration::from_secs_f64(len as f64 * 8.0 / bps));
        *last = due;
    }
    Some(due)
}

/// Sends datagrams from `rx` when due, with `send`.
fn udp_sender(rx: Receiver<Due>, shared: Arc<Shared>, send: impl Fn(&[u8])) {
    let mut heap = BinaryHeap::new();
    loop {
        let wait = heap.peek().map_or(Duration::from_millis(50), |d: &Due| {
            d.at.saturating_duration_since(Instant::now())
        });
        match rx.recv_timeout(wait) {
            Ok(d) => heap.push(d),
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) if heap.is_empty() => return,
            Err(RecvTimeoutError::Disconnected) => {}
        }
        while heap.peek().is_some_and(|d| d.at <= Instant::now()) {
            if let Some(d) = heap.pop() {
                send(&d.data);
                shared
                    .stats
                    .bytes
                    .fetch_add(d.data.len() as u64, Ordering::Relaxed);
                shared.stats.packets.fetch_add(1, Ordering::Relaxed);
            }
        }
        if shared.stopped() {
            return;
        }
    }
}

/// The UDP relay's front: one upstream socket per client address.
fn udp_front(front: UdpSocket, upstream: SocketAddr, shared: Arc<Shared>) {
    let Ok(front) = front.try_clone().map(Arc::new) else {
        return;
    };
    let mut clients: Vec<(SocketAddr, std::sync::mpsc::Sender<Due>)> = Vec::new();
    let mut rng = Rng(shared.impairment().seed);
    let mut last = Instant::now();
    let mut seq = 0u64;
    let mut buf = vec![0u8; 65536];
    while !shared.stopped() {
        let Ok((n, client)) = front.recv_from(&mut buf) else {
            continue;
        };
        let tx = match clients.iter().find(|(a, _)| *a == client) {
            Some((_, tx)) => tx.clone(),
            None => {
                let Ok(back) = UdpSocket::bind("127.0.0.1:0") else {
                    continue;
                };
                if back.connect(upstream).is_err() {
                    continue;
                }
                let _ = back.set_read_timeout(Some(Duration::from_millis(50)));
                let Ok(back) = back.try_clone().map(Arc::new) else {
                    continue;
                };
                // Client → upstream.
                let (tx, rx) = channel::<Due>();
                let (b, s) = (back.clone(), shared.clone());
                let _ = std::thread::Builder::new()
                    .name("relay udp up".into())
                    .spawn(move || {
                        udp_sender(rx, s, |d| {
                            let _ = b.send(d);
                        })
                    });
                // Upstream → client.
                let (dtx, drx) = channel::<Due>();
                let (f, s) = (front.clone(), shared.clone());
                let _ = std::thread::Builder::new()
                    .name("relay udp down".into())
                    .spawn(move || {
                        udp_sender(drx, s, |d| {
                            let _ = f.send_to(d, client);
                        })
                    });
                let s = shared.clone();
                // Each client's replies get a stream of their own (the same seed would drop
                // every new client's first reply alike).
                let stream = 0x5555 + clients.len() as u64;
                let _ = std::thread::Builder::new()
                    .name("relay udp back".into())
                    .spawn(move || {
                        let mut rng = Rng(s.impairment().seed ^ stream.wrapping_mul(0x9E37_79B9));
                        let mut last = Instant::now();
                        let mut seq = 0u64;
                        let mut buf = vec![0u8; 65536];
                        while !s.stopped() {
                            let Ok(n) = back.recv(&mut buf) else { continue };
                            if let Some(at) = schedule(&s, &mut rng, n, &mut last) {
                                seq += 1;
                                if dtx
                                    .send(Due {
                                        at,
                                        seq,
                                        data: buf[..n].to_vec(),
                                    })
                                    .is_err()
                                {
                                    return;
                                }
                            }
                        }
                    });
                clients.push((client, tx.clone()));
                tx
            }
        };
        if let Some(at) = schedule(&shared, &mut rng, n, &mut last) {
            seq += 1;
            let _ = tx.send(Due {
                at,
                seq,
                data: buf[..n].to_vec(),
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn echo_server() -> SocketAddr {
        let l = TcpListener::bind("127.0.0.1:0").expect("binds");
        let addr = l.local_addr().expect("addr");
        std::thread::spawn(move || {
            for s in l.incoming().flatten() {
                std::thread::spawn(move || {
                    let mut s = s;
                    let mut buf = [0u8; 1024];
                    while let Ok(n) = s.read(&mut buf) {
                        if n == 0 || s.write_all(&buf[..n]).is_err() {
                            break;
                        }
                    }
                });
            }
        });
        addr
    }

    fn round_trip(relay: &Relay) -> Duration {
        let mut c = TcpStream::connect(relay.local_addr()).expect("connects");
        c.set_nodelay(true).expect("nodelay");
        let t = Instant::now();
        c.write_all(b"ping").expect("writes");
        let mut buf = [0u8; 4];
        c.read_exact(&mut buf).expect("reads");
        assert_eq!(&buf, b"ping");
        t.elapsed()
    }

    #[test]
    fn tcp_traffic_is_delayed_each_way_and_held_through_a_cut() {
        let relay = Relay::tcp(
            echo_server(),
            Impairment {
                delay_s: 0.05,
                ..Impairment::default()
            },
        )
        .expect("relay");
        let rtt = round_trip(&relay);
        assert!(rtt >= Duration::from_millis(100), "{rtt:?}: 2 x 50 ms");
        relay.set(Impairment::default());
        relay.cut_for(Duration::from_millis(300));
        let rtt = round_trip(&relay);
        assert!(
            rtt >= Duration::from_millis(250),
            "{rtt:?}: held through the cut"
        );
        // Counted after each write: the last echo's count may land just after the read.
        let deadline = Instant::now() + Duration::from_secs(2);
        while relay.stats().bytes.load(Ordering::Relaxed) < 16 && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(5));
        }
        assert!(relay.stats().bytes.load(Ordering::Relaxed) >= 16);
    }

    /// Behind a slow cap the relay holds at most its queue, and then the sender's writes stop
    /// being taken: with a 64 KiB queue at 200 kbit/s a sender that writes as fast as it can
    /// gets only its own and the relay's socket buffers ahead, not the gigabytes loopback
    /// would take in the same time.
    #[test]
    fn a_full_tcp_queue_pushes_back_on_the_sender() {
        let sink = TcpListener::bind("127.0.0.1:0").expect("binds");
        let upstream = sink.local_addr().expect("addr");
        std::thread::spawn(move || {
            for s in sink.incoming().flatten() {
                std::thread::spawn(move || {
                    let mut s = s;
                    let mut buf = [0u8; 4096];
                    while let Ok(n) = s.read(&mut buf) {
                        if n == 0 {
                            break;
                        }
                    }
                });
            }
        });
        let relay = Relay::tcp(
            upstream,
            Impairment {
                bandwidth_bps: Some(200e3),
                queue_bytes: MIN_QUEUE_BYTES,
                ..Impairment::default()
            },
        )
        .expect("relay");
        let mut c = TcpStream::connect(relay.local_addr()).expect("connects");
        c.set_nonblocking(true).expect("nonblocking");
        let chunk = vec![7u8; 64 * 1024];
        let mut written = 0u64;
        let start = Instant::now();
        while start.elapsed() < Duration::from_millis(1500) {
            match c.write(&chunk) {
                Ok(n) => written += n as u64,
                Err(_) => std::thread::sleep(Duration::from_millis(1)),
            }
        }
        let held_max = relay.stats().held_max.load(Ordering::Relaxed);
        let pushed_back = relay.stats().backpressure.load(Ordering::Relaxed);
        eprintln!(
            "taken from the sender {written} B, held at most {held_max} B, pushed back {pushed_back} times"
        );
        assert!(held_max <= MIN_QUEUE_BYTES as u64, "held {held_max}");
        assert!(pushed_back >= 1, "the queue never filled");
        // The sender's send buffer and the relay's receive buffer (Linux autotunes each to a
        // few MiB at most) and the queue; without the limit, loopback takes gigabytes.
        assert!(written < 32 << 20, "{written} bytes taken from the sender");
        // Only what the cap lets through has left the relay (1.5 s at 25 kB/s, and the queue).
        let forwarded = relay.stats().bytes.load(Ordering::Relaxed);
        assert!(forwarded < 200_000, "{forwarded} bytes forwarded");
        assert!(
            relay
                .set_checked(Impairment {
                    queue_bytes: 10,
                    ..Impairment::default()
                })
                .is_err()
        );
    }

    #[test]
    fn udp_loss_is_seeded_and_near_its_rate() {
        let server = UdpSocket::bind("127.0.0.1:0").expect("binds");
        server
            .set_read_timeout(Some(Duration::from_millis(300)))
            .expect("timeout");
        let relay = Relay::udp(
            server.local_addr().expect("addr"),
            Impairment {
                loss: 0.2,
                seed: 7,
                ..Impairment::default()
            },
        )
        .expect("relay");
        // The server reads as they come (a socket's buffer holds only a few hundred).
        let reader = std::thread::spawn(move || {
            let mut got = 0u64;
            let mut buf = [0u8; 8];
            while server.recv_from(&mut buf).is_ok() {
                got += 1;
            }
            got
        });
        let client = UdpSocket::bind("127.0.0.1:0").expect("binds");
        // Paced, so that no socket buffer overflows: every datagram is the relay's to drop.
        for i in 0..1000u32 {
            client
                .send_to(&i.to_le_bytes(), relay.local_addr())
                .expect("sends");
            std::thread::sleep(Duration::from_micros(200));
        }
        let got = reader.join().expect("the reader");
        let dropped = relay.stats().dropped.load(Ordering::Relaxed);
        let forwarded = relay.stats().packets.load(Ordering::Relaxed);
        assert_eq!(got, forwarded, "every forwarded datagram arrives");
        assert_eq!(got + dropped, 1000, "{got} + {dropped}");
        assert!((150..250).contains(&dropped), "{dropped} of 1000 at 20 %");
    }
}
