//! `landing link setup-signing`: installs the stack's MAVLink signing key on the
//! autopilot (SETUP_SIGNING, as QGroundControl does), from px4-link's own address, then
//! waits for the autopilot's heartbeats to arrive signed with that key: the proof that
//! it took it. Run it with the stack stopped (it speaks from px4-link's port).

use std::net::UdpSocket;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use mavlink::MavHeader;
use mavlink::dialects::common::{MavMessage, SETUP_SIGNING_DATA};
use px4_link::config::LinkAddress;
use px4_protocol::codec::{Guard, StreamDecoder};
use px4_protocol::signing::{KEY_LEN, Signer, SigningKey, timestamp_of_unix_ns};
use stack_config::deploy_dir;

use crate::config_cmd::StackConfig;

/// `landing link setup-signing` flags.
#[derive(Debug, clap::Args)]
pub struct SetupSigningArgs {
    /// Stack configuration (default: deploy/config/landing.toml): `[px4_link] link` and
    /// `remote` say where the autopilot is, `signing_key` which key to install.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Make a new random key first when the key file does not exist (owner-only
    /// permissions); an existing key is never overwritten.
    #[arg(long)]
    pub generate: bool,
    /// How long to wait for the autopilot's signed heartbeat, s (0.5-60).
    #[arg(long, default_value_t = 5.0)]
    pub timeout_s: f64,
}

/// A new random key, from the kernel's generator.
fn random_key() -> Result<SigningKey> {
    use std::io::Read;
    let mut bytes = [0u8; KEY_LEN];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut f| f.read_exact(&mut bytes))
        .context("reading /dev/urandom")?;
    Ok(SigningKey::from_bytes(bytes))
}

/// Installs the key; prints one line saying so.
pub fn setup_signing(args: &SetupSigningArgs) -> Result<()> {
    if !(args.timeout_s.is_finite() && (0.5..=60.0).contains(&args.timeout_s)) {
        bail!("--timeout-s {}: allowed 0.5 to 60", args.timeout_s);
    }
    let path = args
        .config
        .clone()
        .unwrap_or_else(|| deploy_dir().join("config").join("landing.toml"));
    let raw: StackConfig = stack_config::load(&path)?;
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."));
    let Some(key_path) = raw.px4_link.signing_key_path(dir) else {
        bail!(
            "{}: [px4_link] signing_key is empty (allowed: a key file, e.g. signing_key = \"mavlink.key\")",
            path.display()
        );
    };
    if args.generate && !key_path.exists() {
        random_key()?
            .save(&key_path)
            .with_context(|| format!("writing {}", key_path.display()))?;
        eprintln!("made a new key in {}", key_path.display());
    }
    let key = SigningKey::load(&key_path)?;
    let listen = match raw
        .px4_link
        .address()
        .map_err(|e| anyhow::anyhow!(e.message))?
    {
        LinkAddress::Udp(a) => a,
        LinkAddress::Serial { path, .. } => bail!(
            "[px4_link] link is serial ({}): setup-signing speaks UDP only (allowed: a udp: link; over USB, install the key with QGroundControl)",
            path.display()
        ),
    };
    let remote = raw
        .px4_link
        .remote_address()
        .map_err(|e| anyhow::anyhow!(e.message))?;
    let sock = UdpSocket::bind(listen)
        .with_context(|| format!("binding {listen} (px4-link's address): stop the stack first"))?;
    sock.set_read_timeout(Some(Duration::from_millis(50)))?;

    let unix_at_zero = runtime::unix_ns_at_monotonic_zero();
    let now = runtime::monotonic_ns();
    let initial = timestamp_of_unix_ns(unix_at_zero.saturating_add(now));
    let setup = MavMessage::SETUP_SIGNING(SETUP_SIGNING_DATA {
        initial_timestamp: initial,
        target_system: 1,
        target_component: 1,
        secret_key: *key.bytes(),
    });
    // Sent unsigned: an autopilot without a key takes it so. One that already signs
    // takes only a frame signed with its current key, so the same key again is signed.
    let mut unsigned = Guard::open();
    let mut signed = Guard::new(None, Some(Signer::new(key.clone(), 1, unix_at_zero)));
    let header = MavHeader {
        system_id: 1,
        component_id: 191,
        sequence: 0,
    };
    let mut frames = Vec::new();
    unsigned.encode(&mut frames, header, &setup, now)?;
    signed.encode(&mut frames, header, &setup, now)?;

    // The proof: a heartbeat from the autopilot signed with this key.
    let mut check = Guard::new(Some((1, 1)), Some(Signer::new(key, 0, unix_at_zero)));
    let mut decoder = StreamDecoder::new();
    let end = Instant::now() + Duration::from_secs_f64(args.timeout_s);
    let mut next_send = Instant::now();
    let mut buf = [0u8; 2048];
    let mut heard = 0u64;
    while Instant::now() < end {
        if Instant::now() >= next_send {
            sock.send_to(&frames, remote)
                .with_context(|| format!("sending to {remote}"))?;
            next_send = Instant::now() + Duration::from_millis(500);
        }
        let Ok((n, from)) = sock.recv_from(&mut buf) else {
            continue;
        };
        if from != remote {
            continue;
        }
        heard += 1;
        let mut msgs = Vec::new();
        decoder.push_datagram(&buf[..n], runtime::monotonic_ns(), &mut check, &mut msgs);
        if msgs
            .iter()
            .any(|(_, m)| matches!(m, MavMessage::HEARTBEAT(_)))
        {
            println!(
                "the autopilot at {remote} signs with the key in {} (its heartbeat checks out)",
                key_path.display()
            );
            return Ok(());
        }
    }
    if heard == 0 {
        bail!(
            "no answer from the autopilot at {remote} in {} s ([px4_link] remote)",
            args.timeout_s
        );
    }
    bail!(
        "the autopilot at {remote} answered but not signed with the key in {} ({} datagrams): it did not take the key (already signing with another one?)",
        key_path.display(),
        heard
    )
}
