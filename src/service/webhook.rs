//! Webhooks, signed as the Standard Webhooks specification says: headers `webhook-id`,
//! `webhook-timestamp`, `webhook-signature: v1,<base64 HMAC-SHA256(secret, "{id}.{ts}.{body}")>`,
//! where the secret is `whsec_<base64 key>`. Sent from the store's outbox (a job's end queues
//! its delivery in the same atomic step), with retries and exponential backoff;
//! only http(s) targets, and only globally routable unicast addresses unless the configuration
//! allows private ones: a literal address is checked on submit and on delivery, a name by the
//! client's own resolver, which hands the connector only the addresses it checked (so a name
//! cannot be re-pointed between the check and the connection).

use super::domain::now_ms;
use super::metrics::Metrics;
use super::store::{Delivery, Store};
use super::views::{job_json, rfc3339};
use base64::Engine;
use hmac::{Hmac, Mac};
use sha2::Sha256;
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr};
use std::sync::Arc;
use std::time::Duration;

/// The signing key: `secret` when given; else the one the store keeps for every process on
/// it (PostgreSQL: the first replica's, so that all sign alike); else the one kept in
/// `data_dir/webhook_secret`, generated there on first start.
pub fn signing_key(
    secret: Option<&str>,
    store: &dyn Store,
    data_dir: &std::path::Path,
) -> Result<Vec<u8>, String> {
    // An empty value (an unset variable passed on by a deployment file) means none.
    if let Some(s) = secret.filter(|s| !s.trim().is_empty()) {
        return decode_secret(s);
    }
    if let Some(shared) = store
        .shared_webhook_secret(&generate_secret())
        .map_err(|e| format!("webhook secret: {e}"))?
    {
        return decode_secret(&shared);
    }
    let path = data_dir.join("webhook_secret");
    if let Ok(s) = std::fs::read_to_string(&path) {
        return decode_secret(&s);
    }
    let secret = generate_secret();
    std::fs::write(&path, &secret).map_err(|e| format!("{}: {e}", path.display()))?;
    tracing::info!(path = %path.display(), "generated a webhook signing secret");
    decode_secret(&secret)
}

/// A new random `whsec_<base64 of 32 bytes>`.
fn generate_secret() -> String {
    let mut key = Vec::with_capacity(32);
    key.extend_from_slice(uuid::Uuid::new_v4().as_bytes());
    key.extend_from_slice(uuid::Uuid::new_v4().as_bytes());
    format!(
        "whsec_{}",
        base64::engine::general_purpose::STANDARD.encode(&key)
    )
}

/// How long a sender holds a delivery: more than one attempt's timeout (10 s).
const DELIVERY_LEASE_MS: i64 = 15_000;
/// How often an idle sender looks at the outbox.
const OUTBOX_POLL: Duration = Duration::from_millis(200);
/// Most deliveries in flight per process.
const IN_FLIGHT: usize = 16;

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

/// Whether an address must not be called: anything but a globally routable unicast address
/// (an allow-list, so that ranges nobody thought of are refused too).
pub fn is_private(ip: IpAddr) -> bool {
    match ip {
        IpAddr::V4(v) => !is_global_v4(v),
        IpAddr::V6(v) => match v.to_ipv4_mapped() {
            Some(v4) => !is_global_v4(v4),
            None => !is_global_v6(v),
        },
    }
}

/// IPv4 outside every special-purpose block of the IANA registry (RFC 6890 and successors)
/// that is not globally reachable, and outside multicast and the reserved 240/4.
fn is_global_v4(v: Ipv4Addr) -> bool {
    let [a, b, c, _] = v.octets();
    let refused = a == 0 // "this network"
        || a == 10
        || (a == 100 && (b & 0xc0) == 64) // 100.64/10, shared (CGNAT)
        || a == 127
        || (a == 169 && b == 254) // link-local (cloud metadata)
        || (a == 172 && (b & 0xf0) == 16)
        || (a == 192 && b == 0 && c == 0) // 192.0.0/24, protocol assignments
        || (a == 192 && b == 0 && c == 2) // documentation
        || (a == 192 && b == 88 && c == 99) // 6to4 relay anycast
        || (a == 192 && b == 168)
        || (a == 198 && (b & 0xfe) == 18) // 198.18/15, benchmarking
        || (a == 198 && b == 51 && c == 100) // documentation
        || (a == 203 && b == 0 && c == 113) // documentation
        || a >= 224; // multicast 224/4, reserved 240/4, broadcast
    !refused
}

/// IPv6 global unicast (2000::/3) outside the blocks inside it that are not globally
/// reachable or that embed an IPv4 address the check would not see (6to4, Teredo).
fn is_global_v6(v: Ipv6Addr) -> bool {
    let s = v.segments();
    let refused = (s[0] & 0xe000) != 0x2000 // not 2000::/3: loopback, ULA, link-local,
        // site-local, multicast, IPv4-compatible ::a.b.c.d, NAT64 64:ff9b::/96, …
        || (s[0] == 0x2001 && s[1] < 0x0200) // 2001::/23, IETF protocol assignments (Teredo, ORCHID, …)
        || (s[0] == 0x2001 && s[1] == 0x0db8) // documentation
        || s[0] == 0x2002 // 6to4
        || (s[0] & 0xfff0) == 0x3ff0; // 3fff::/20, documentation
    !refused
}

/// A name that resolves only to refused addresses.
#[derive(Debug)]
struct PrivateTarget(String);

impl std::fmt::Display for PrivateTarget {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} resolves only to private or reserved addresses",
            self.0
        )
    }
}

impl std::error::Error for PrivateTarget {}

/// The webhook client's resolver: the addresses of a name that may be called, and only
/// those, are what the connector gets.
struct CheckedResolver {
    allow_private: bool,
}

impl reqwest::dns::Resolve for CheckedResolver {
    fn resolve(&self, name: reqwest::dns::Name) -> reqwest::dns::Resolving {
        let allow_private = self.allow_private;
        Box::pin(async move {
            let host = name.as_str().to_string();
            let found: Vec<SocketAddr> =
                tokio::net::lookup_host((host.as_str(), 0)).await?.collect();
            let usable: Vec<SocketAddr> = found
                .into_iter()
                .filter(|a| allow_private || !is_private(a.ip()))
                .collect();
            if usable.is_empty() {
                return Err(
                    Box::new(PrivateTarget(host)) as Box<dyn std::error::Error + Send + Sync>
                );
            }
            Ok(Box::new(usable.into_iter()) as reqwest::dns::Addrs)
        })
    }
}

/// Whether a failed request was refused by [`CheckedResolver`] (not worth retrying).
fn refused_target(e: &reqwest::Error) -> Option<String> {
    let mut cause: Option<&(dyn std::error::Error + 'static)> = Some(e);
    while let Some(c) = cause {
        if let Some(p) = c.downcast_ref::<PrivateTarget>() {
            return Some(p.to_string());
        }
        cause = c.source();
    }
    None
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
                // `localhost.` is `localhost` (a fully qualified name).
                let d = d.trim_end_matches('.').to_ascii_lowercase();
                if d == "localhost" || d.ends_with(".localhost") {
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
        // No proxy from the environment: a proxy would resolve the target itself, past the
        // resolver's check.
        let client = reqwest::Client::builder()
            .no_proxy()
            .dns_resolver(Arc::new(CheckedResolver { allow_private }))
            .timeout(Duration::from_secs(10))
            .redirect(reqwest::redirect::Policy::none())
            .user_agent(concat!("flatmesh/", env!("CARGO_PKG_VERSION")))
            .build()
            // Never a default client in its place: that one would skip the address checks.
            .expect("the webhook HTTP client cannot be built (TLS initialisation failed)");
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

    /// The base URL of a job's links: the configured public URL, else the one its submitter
    /// used.
    fn base_for<'a>(&'a self, job: &'a crate::service::domain::JobRecord) -> &'a str {
        if self.base.is_empty() {
            job.base_url.as_deref().unwrap_or("")
        } else {
            &self.base
        }
    }

    /// Whether private targets are allowed.
    pub fn allow_private(&self) -> bool {
        self.allow_private
    }

    /// Send the outbox (every process on one store shares it): claim due deliveries as
    /// `worker`, POST each to its job's callback, and record it done, due again after the
    /// next backoff step, or given up. A delivery whose sender died is taken by another when
    /// its lease runs out, so every ended job's webhook is sent, once unless a sender dies
    /// mid-request (its `webhook-id` is the same on every attempt, for receivers to dedupe).
    pub fn start(self: &Arc<Self>, store: Arc<dyn Store>, worker: String) {
        let me = Arc::clone(self);
        self.runtime.spawn(async move {
            let slots = Arc::new(tokio::sync::Semaphore::new(IN_FLIGHT));
            loop {
                let Ok(slot) = Arc::clone(&slots).acquire_owned().await else {
                    return;
                };
                let (st, w) = (Arc::clone(&store), worker.clone());
                let claimed = tokio::task::spawn_blocking(move || {
                    st.claim_delivery(&w, now_ms(), DELIVERY_LEASE_MS)
                })
                .await;
                match claimed {
                    Ok(Ok(Some(d))) => {
                        let (me, st, w) = (Arc::clone(&me), Arc::clone(&store), worker.clone());
                        tokio::spawn(async move {
                            me.send(st, &w, d).await;
                            drop(slot);
                        });
                    }
                    other => {
                        if let Ok(Err(e)) = other {
                            tracing::warn!(error = %e, "cannot read the webhook outbox");
                        }
                        drop(slot);
                        tokio::time::sleep(OUTBOX_POLL).await;
                    }
                }
            }
        });
    }

    /// One attempt at one delivery, and its record in the store.
    async fn send(&self, store: Arc<dyn Store>, worker: &str, d: Delivery) {
        let st = Arc::clone(&store);
        let job_id = d.job_id.clone();
        let job = match tokio::task::spawn_blocking(move || st.get_job(&job_id)).await {
            Ok(Ok(j)) => j,
            // The store did not answer: the lease runs out and it is tried again.
            _ => return,
        };
        let outcome = match job
            .as_ref()
            .and_then(|j| Some((j, j.callback_url.clone()?)))
        {
            // The job (or its callback) is gone: nothing to send, nothing to count.
            None => {
                let w = worker.to_string();
                let _ = tokio::task::spawn_blocking(move || store.end_delivery(d.id, &w)).await;
                return;
            }
            Some((job, url)) => {
                let payload = serde_json::json!({
                    "type": d.event,
                    "timestamp": rfc3339(now_ms()),
                    "data": job_json(job, None, self.base_for(job)),
                });
                let body = serde_json::to_vec(&payload).unwrap_or_default();
                let msg_id = format!("msg_{}_{}", job.id, d.id);
                let r = deliver(
                    &self.client,
                    &url,
                    &self.key,
                    &msg_id,
                    &body,
                    self.allow_private,
                )
                .await;
                match &r {
                    Ok(()) => {
                        tracing::info!(job = %job.id, %url, attempt = d.attempts, "webhook delivered")
                    }
                    Err((msg, _)) => {
                        tracing::warn!(job = %job.id, %url, attempt = d.attempts, error = %msg, "webhook failed")
                    }
                }
                r.map_err(|(_, retry)| retry)
            }
        };
        let next = self.backoff.get(d.attempts as usize).copied();
        let again = match (&outcome, next) {
            (Err(true), Some(wait)) => Some(now_ms() + wait.as_millis() as i64),
            _ => None,
        };
        if again.is_none() {
            self.metrics.webhook(outcome.is_ok());
        }
        let w = worker.to_string();
        let recorded = tokio::task::spawn_blocking(move || match again {
            Some(at) => store.retry_delivery(d.id, &w, at),
            None => store.end_delivery(d.id, &w),
        })
        .await;
        if let Ok(Err(e)) = recorded {
            tracing::warn!(error = %e, "cannot record a webhook delivery");
        }
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
    // Literal addresses are checked here, names by the client's resolver.
    let u = check_url(url, allow_private).map_err(|e| (e, false))?;
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
        .map_err(|e| match refused_target(&e) {
            Some(why) => (why, false),
            None => (e.to_string(), true),
        })?;
    let s = res.status();
    if s.is_success() {
        Ok(())
    } else {
        // 410 Gone: the receiver does not want it any more.
        Err((format!("status {s}"), s.as_u16() != 410))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Only globally routable unicast addresses may be called: every special-purpose block
    /// the issue found missing, and the usual ones, in each form.
    #[test]
    fn only_global_unicast_addresses_are_callable() {
        let refused = [
            "0.1.2.3",
            "10.0.0.1",
            "100.64.0.1",
            "127.0.0.1",
            "169.254.169.254",
            "172.16.0.1",
            "172.31.255.255",
            "192.0.0.8",
            "192.0.2.1",
            "192.88.99.1",
            "192.168.1.1",
            "198.18.0.1",
            "198.19.255.255",
            "198.51.100.1",
            "203.0.113.1",
            "224.0.0.1",
            "239.1.1.1",
            "240.0.0.1",
            "255.255.255.255",
            "::",
            "::1",
            "::127.0.0.1",
            "::ffff:10.0.0.1",
            "::ffff:127.0.0.1",
            "64:ff9b::7f00:1",
            "100::1",
            "fc00::1",
            "fd12::1",
            "fe80::1",
            "fec0::1",
            "ff02::1",
            "2001::1",
            "2001:db8::1",
            "2002:7f00:1::1",
            "3fff::1",
        ];
        let allowed = [
            "8.8.8.8",
            "1.1.1.1",
            "100.128.0.1",
            "172.32.0.1",
            "192.0.1.1",
            "198.20.0.1",
            "223.255.255.254",
            "::ffff:8.8.8.8",
            "2606:4700:4700::1111",
            "2a00:1450:4001::1",
        ];
        for a in refused {
            assert!(is_private(a.parse().unwrap()), "{a} is callable");
        }
        for a in allowed {
            assert!(!is_private(a.parse().unwrap()), "{a} is refused");
        }
    }

    /// The resolver hands over only the addresses that may be called, and refuses a name with
    /// none (as an error the delivery does not retry).
    #[tokio::test]
    async fn resolver_hands_over_only_callable_addresses() {
        use reqwest::dns::Resolve;
        let name = || "localhost".parse::<reqwest::dns::Name>().unwrap();
        let strict = CheckedResolver {
            allow_private: false,
        };
        let err = match strict.resolve(name()).await {
            Ok(addrs) => panic!("localhost resolved to {:?}", addrs.collect::<Vec<_>>()),
            Err(e) => e,
        };
        assert!(err.downcast_ref::<PrivateTarget>().is_some(), "{err}");
        let open = CheckedResolver {
            allow_private: true,
        };
        let addrs: Vec<SocketAddr> = open.resolve(name()).await.unwrap().collect();
        assert!(!addrs.is_empty() && addrs.iter().all(|a| a.ip().is_loopback()));
    }
}
