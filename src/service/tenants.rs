//! API keys and tenants. A key `name:secret` acts for tenant `name`; a bare key for the
//! default tenant `""`, which is also every request's when no keys are configured (so data
//! stored before tenants existed stays with the keys that made it). A tenant sees, lists,
//! downloads, cancels and deletes only its own meshes and jobs; another's are 404, as if
//! they did not exist. Idempotency keys and upload deduplication are per tenant too.

use sha2::{Digest, Sha256};

/// The tenant a request acts for, put into the request's extensions by the auth layer.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Tenant(pub String);

/// One configured API key.
#[derive(Debug, Clone)]
pub struct ApiKey {
    /// Tenant it acts for (`""`: the default tenant).
    pub tenant: String,
    /// SHA-256 of the secret (compared in full, so that time tells nothing).
    digest: [u8; 32],
}

/// Parse `--api-key` values: `secret` or `name:secret`, names of 1 to 64 ASCII letters,
/// digits, `.`, `_` or `-`. An empty key or secret, a bad name or a secret given twice is
/// an error naming it (by position: secrets are never echoed).
pub fn parse_api_keys(given: &[String]) -> Result<Vec<ApiKey>, String> {
    let mut out: Vec<ApiKey> = Vec::with_capacity(given.len());
    for (i, k) in given.iter().enumerate() {
        let n = i + 1;
        let (tenant, secret) = match k.split_once(':') {
            Some((name, secret)) => (name, secret),
            None => ("", k.as_str()),
        };
        if secret.trim().is_empty() {
            return Err(format!(
                "API key {n}: empty (give non-empty keys, comma-separated, or none to run \
                 without authentication)"
            ));
        }
        let name_ok = (1..=64).contains(&tenant.len())
            && tenant
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b"._-".contains(&b));
        if k.contains(':') && !name_ok {
            return Err(format!(
                "API key {n}: the tenant name before `:` must be 1 to 64 letters, digits, \
                 `.`, `_` or `-`"
            ));
        }
        let digest: [u8; 32] = Sha256::digest(secret.as_bytes()).into();
        if out.iter().any(|o| o.digest == digest) {
            return Err(format!("API key {n}: the same secret is given twice"));
        }
        out.push(ApiKey {
            tenant: tenant.to_string(),
            digest,
        });
    }
    Ok(out)
}

/// The key whose secret is `given`. Every key's digest is compared in full, so the time
/// taken tells nothing of a key's length or of how much of it matched.
pub fn find_key<'a>(keys: &'a [ApiKey], given: &str) -> Option<&'a ApiKey> {
    let g: [u8; 32] = Sha256::digest(given.as_bytes()).into();
    keys.iter().fold(None, |found, k| {
        let diff = k
            .digest
            .iter()
            .zip(g.iter())
            .fold(0u8, |acc, (a, b)| acc | (a ^ b));
        if diff == 0 {
            Some(k)
        } else {
            found
        }
    })
}

/// An idempotency key as stored: the client's, after its tenant (so that two tenants may use
/// the same key). A header value never holds the separator (a control character).
pub fn scoped_key(tenant: &Tenant, key: &str) -> String {
    if tenant.0.is_empty() {
        key.to_string()
    } else {
        format!("{}\u{1f}{key}", tenant.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn keys(k: &[&str]) -> Result<Vec<ApiKey>, String> {
        parse_api_keys(&k.iter().map(|s| s.to_string()).collect::<Vec<_>>())
    }

    #[test]
    fn keys_name_their_tenant_and_match_exactly() {
        let ks = keys(&["k1", "acme:s3cret", "b-2.x_y:other"]).unwrap();
        assert_eq!(find_key(&ks, "k1").unwrap().tenant, "");
        assert_eq!(find_key(&ks, "s3cret").unwrap().tenant, "acme");
        assert_eq!(find_key(&ks, "other").unwrap().tenant, "b-2.x_y");
        for g in ["k", "k12", "K1", "", "acme:s3cret", "s3cre", "acme"] {
            assert!(find_key(&ks, g).is_none(), "{g:?}");
        }
    }

    #[test]
    fn bad_keys_are_refused_without_echoing_them() {
        for (k, why) in [
            (vec!["k1", ""], "API key 2: empty"),
            (vec!["acme:"], "API key 1: empty"),
            (vec![":s3cret"], "tenant name"),
            (vec!["a b:s3cret"], "tenant name"),
            (vec!["x:s3cret", "y:s3cret"], "API key 2: the same secret"),
        ] {
            let e = keys(&k).unwrap_err();
            assert!(e.contains(why), "{k:?}: {e}");
            assert!(!e.contains("s3cret"), "{e}");
        }
    }

    #[test]
    fn scoped_keys_of_tenants_never_collide() {
        let a = scoped_key(&Tenant("a".into()), "x");
        let default = scoped_key(&Tenant::default(), "a:x");
        assert_ne!(a, default);
        assert_eq!(scoped_key(&Tenant::default(), "k"), "k");
    }
}
