//! Opaque page tokens: the position (a sequence number) and the filter it was issued
//! for, so that a token is neither made up by clients nor reused with another filter.

use super::sha256_hex;
use base64::Engine;

const B64: base64::engine::GeneralPurpose = base64::engine::general_purpose::URL_SAFE_NO_PAD;

fn fingerprint(filter: &str) -> String {
    sha256_hex(filter.as_bytes())[..12].to_string()
}

/// The token after position `seq` of the listing with `filter`.
pub fn encode(seq: i64, filter: &str) -> String {
    B64.encode(format!("p1:{seq}:{}", fingerprint(filter)))
}

/// The position a token stands for; `Err` with why it is refused.
pub fn decode(token: &str, filter: &str) -> Result<i64, &'static str> {
    let raw = B64
        .decode(token)
        .ok()
        .and_then(|b| String::from_utf8(b).ok())
        .ok_or("not a page token from this API")?;
    let mut parts = raw.splitn(3, ':');
    let (Some("p1"), Some(seq), Some(fp)) = (parts.next(), parts.next(), parts.next()) else {
        return Err("not a page token from this API");
    };
    let seq: i64 = seq.parse().map_err(|_| "not a page token from this API")?;
    if fp != fingerprint(filter) {
        return Err("this page token belongs to a listing with other filters");
    }
    Ok(seq)
}

#[cfg(test)]
mod tests {
    #[test]
    fn tokens_round_trip_and_are_bound_to_their_filter() {
        let t = super::encode(42, "status=queued");
        assert_eq!(super::decode(&t, "status=queued"), Ok(42));
        assert!(super::decode(&t, "status=running").is_err());
        assert!(super::decode("42", "").is_err());
        assert!(super::decode("!!", "").is_err());
        assert!(!t.contains("42"), "{t}");
    }
}
