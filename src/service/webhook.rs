//! Webhooks, signed as the Standard Webhooks specification says: headers `webhook-id`,
//! `webhook-timestamp`, `webhook-signature: v1,<base64 HMAC-SHA256(secret, "{id}.{ts}.{body}")>`,
//! where the secret is `whsec_<base64 key>`. Delivered with retries and exponential backoff;
//! only http(s) targets, and private, loopback and link-local addresses are refused unless the
//! configuration allows them (checked on submit for literal addresses and again on delivery
//! after DNS resolution).

use super::domain::{now_ms, JobRecord};
use super::metrics::Metrics;
use super::views::{job_json, rfc3339};
use base64::Engine;
use hmac::{Hmac, Mac};
use sha2::Sha256;
use std::net::IpAddr;
use std::sync::Arc;
use std::time::Duration;

/// The signing key: `secret` when given, else the one kept in `data_dir/webhook_secret`,
/// generated there on first start.
pub fn signing_key(secret: Option<&str>, data_dir: &std::path::Path) -> Result<Vec<u8>, String> {
    if let Some(s) = secret {
        return decode_secret(s);
    }
    let path = data_dir.join("webhook_secret");
    if let Ok(s) = std::fs::read_to_string(&path) {
        return decode_secret(&s);
    }
    let mut key = Vec::with_capacity(32);
    key.extend_from_slice(uuid::Uuid::new_v4().as_bytes());
    key.extend_from_slice(uuid::Uuid::new_v4().as_bytes());
    let secret = format!(
        "whsec_{}",
        base64::engine::general_purpose::STANDARD.encode(&key)
    );
    std::fs::write(&path, secret).map_err(|e| format!("{}: {e}", path.display()))?;
    tracing::info!(path = %path.display(), "generated a webhook signing secret");
    Ok(key)
}

/// Webhook sender.
pub struct Webhooks {
    key: Vec<u8>,
    allow_private: bool,
    client: reqwest::Client,
    runtime: tokio::runtime::Handle,
    metrics: Arc<Metrics>,
    /// Delays between attempts (the first attempt is immediate).
    pub backoff: Vec<Duration>,
    /// Public base URL of the API, for links in the payload.
    pub base: String,
}

/// Decode a `whsec_…` secret (or bare base64) into the HMAC key.
pub fn decode_secret(secret: &str) -> Result<Vec<u8>, String> {
    base64::engine::general_purpose::STANDARD
        .decode(secret.trim().trim_start_matches("whsec_"))
        .map_err(|e| format!("webhook secret is not whsec_<base64>: {e}"))
}

/// `v1,<base64 signature>` of a message.
pub fn sign(key: &[u8], id: &str, timestamp: i64, body: &[u8]) -> String {
    let mut mac = Hmac::<Sha256>::new_from_slice(key).expect("HMAC takes any key length");
    mac.update(id.as_bytes());
    mac.update(b".");
    mac.update(timestamp.to_string().as_bytes());
    mac.update(b".");
    mac.update(body);
    format!(
        "v1,{}",
        base64::engine::general_purpose::STANDARD.encode(mac.finalize().into_bytes())
    )
}

/// Whether an address must not be called (loopback, private, link-local, unspecified, …).
pub fn is_private(ip: IpAddr) -> bool {
    match ip {
        IpAddr::V4(v) => {
            v.is_private()
                || v.is_loopback()
                || v.is_link_local()
                || v.is_unspecified()
                || v.is_broadcast()
                || v.is_documentation()
                || v.octets()[0] == 0
                || (v.octets()[0] == 100 && (v.octets()[1] & 0xc0) == 64) // 100.64/10 CGNAT
        }
        IpAddr::V6(v) => {
            if let Some(v4) = v.to_ipv4_mapped() {
                return is_private(IpAddr::V4(v4));
            }
            let s = v.segments()[0];
            v.is_loopback()
                || v.is_unspecified()
                || (s & 0xfe00) == 0xfc00 // unique local
                || (s & 0xffc0) == 0xfe80 // link-local
        }
    }
}

/// Check a callback URL at submit time; the message names what is wrong.
pub fn check_url(url: &str, allow_private: bool) -> Result<reqwest::Url, String> {
    let u = reqwest::Url::parse(url).map_err(|e| format!("not a URL: {e}"))?;
    if !matches!(u.scheme(), "http" | "https") {
        return Err(format!(
            "scheme `{}` refused: only http and https",
            u.scheme()
        ));
    }
    let host = u.host().ok_or("the URL has no host")?;
    if !allow_private {
        let ip = match host {
            url::Host::Ipv4(a) => Some(IpAddr::V4(a)),
            url::Host::Ipv6(a) => Some(IpAddr::V6(a)),
            url::Host::Domain(d) => {
                if d.eq_ignore_ascii_case("localhost") || d.ends_with(".localhost") {
                    return Err("loopback host refused".into());
                }
                None
            }
        };
        if ip.is_some_and(is_private) {
            return Err("private, loopback or link-local address refused".into());
        }
    }
    Ok(u)
}

impl Webhooks {
    /// A sender with the given secret key.
    pub fn new(
        key: Vec<u8>,
        allow_private: bool,
        runtime: tokio::runtime::Handle,
        metrics: Arc<Metrics>,
    ) -> Webhooks {
        let client = reqwest::Client::builder()
            .timeout(Duration::from_secs(10))
            .redirect(reqwest::redirect::Policy::none())
            .user_agent(concat!("flatmesh/", env!("CARGO_PKG_VERSION")))
            .build()
            .unwrap_or_default();
        Webhooks {
            key,
            allow_private,
            client,
            runtime,
            metrics,
            backoff: [1, 5, 30, 120, 600]
                .iter()
                .map(|s| Duration::from_secs(*s))
                .collect(),
            base: String::new(),
        }
    }

    /// Whether private targets are allowed.
    pub fn allow_private(&self) -> bool {
        self.allow_private
    }

    /// Send the job's final state to its callback, if it has one (in the background).
    pub fn notify(&self, job: &JobRecord) {
        let Some(url) = job.callback_url.clone() else {
            return;
        };
        let payload = serde_json::json!({
            "type": format!("job.{}", job.status.as_str()),
            "timestamp": rfc3339(now_ms()),
            "data": job_json(job, None, &self.base),
        });
        let body = serde_json::to_vec(&payload).unwrap_or_default();
        let msg_id = format!("msg_{}", uuid::Uuid::new_v4().simple());
        let client = self.client.clone();
        let key = self.key.clone();
        let backoff = self.backoff.clone();
        let allow_private = self.allow_private;
        let metrics = Arc::clone(&self.metrics);
        let job_id = job.id.clone();
        self.runtime.spawn(async move {
            for attempt in 0..=backoff.len() {
                if attempt > 0 {
                    tokio::time::sleep(backoff[attempt - 1]).await;
                }
                match deliver(&client, &url, &key, &msg_id, &body, allow_private).await {
                    Ok(()) => {
                        metrics.webhook(true);
                        tracing::info!(job = %job_id, %url, attempt, "webhook delivered");
                        return;
                    }
                    Err((msg, retry)) => {
                        tracing::warn!(job = %job_id, %url, attempt, error = %msg, "webhook failed");
                        if !retry {
                            break;
                        }
                    }
                }
            }
            metrics.webhook(false);
        });
    }
}

/// One attempt. `Err((why, retry))`.
async fn deliver(
    client: &reqwest::Client,
    url: &str,
    key: &[u8],
    msg_id: &str,
    body: &[u8],
    allow_private: bool,
) -> Result<(), (String, bool)> {
    let u = check_url(url, allow_private).map_err(|e| (e, false))?;
    if !allow_private {
        // Resolve now and refuse names that point inside (DNS can change after submit).
        let host = u.host_str().unwrap_or_default().to_string();
        let port = u.port_or_known_default().unwrap_or(80);
        let addrs = tokio::net::lookup_host((host.as_str(), port))
            .await
            .map_err(|e| (format!("cannot resolve {host}: {e}"), true))?;
        for a in addrs {
            if is_private(a.ip()) {
                return Err((format!("{host} resolves to a private address"), false));
            }
        }
    }
    let ts = now_ms() / 1000;
    let res = client
        .post(u)
        .header("content-type", "application/json")
        .header("webhook-id", msg_id)
        .header("webhook-timestamp", ts.to_string())
        .header("webhook-signature", sign(key, msg_id, ts, body))
        .body(body.to_vec())
        .send()
        .await
        .map_err(|e| (e.to_string(), true))?;
    let s = res.status();
    if s.is_success() {
        Ok(())
    } else {
        // 410 Gone: the receiver does not want it any more.
        Err((format!("status {s}"), s.as_u16() != 410))
    }
}
