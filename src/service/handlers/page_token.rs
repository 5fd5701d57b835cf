//! Opaque page tokens: the position (a sequence number) and the filter it was issued
//! for, so that a token is neither made up by clients nor reused with another filter.

use super::sha256_hex;
use base64::Engine;

const B64: base64::engine::GeneralPurpose = base64::engine::general_purpose::URL_SAFE_NO_PAD;

fn fingerprint(filter: &str) -> String {
    sha256_hex(filter.as_bytes())[..12].to_string()
}

const NOT_OURS: &str = "not a page token from this API";

/// A token for position `pos` (no `:` in it) of the listing with `filter`.
fn encode_raw(pos: &str, filter: &str) -> String {
    B64.encode(format!("p1:{}:{pos}", fingerprint(filter)))
}

/// The position a token stands for; `Err` with why it is refused.
fn decode_raw(token: &str, filter: &str) -> Result<String, &'static str> {
    let raw = B64
        .decode(token)
        .ok()
        .and_then(|b| String::from_utf8(b).ok())
        .ok_or(NOT_OURS)?;
    let mut parts = raw.splitn(3, ':');
    let (Some("p1"), Some(fp), Some(pos)) = (parts.next(), parts.next(), parts.next()) else {
        return Err(NOT_OURS);
    };
    if fp != fingerprint(filter) {
        return Err("this page token belongs to a listing with other filters");
    }
    Ok(pos.to_string())
}

/// The token after sequence number `seq` of the listing with `filter`.
pub fn encode(seq: i64, filter: &str) -> String {
    encode_raw(&seq.to_string(), filter)
}

/// The sequence number a token stands for.
pub fn decode(token: &str, filter: &str) -> Result<i64, &'static str> {
    decode_raw(token, filter)?.parse().map_err(|_| NOT_OURS)
}

/// The token after the item created at `at` with id `id` (ids have no `:`).
pub fn encode_position(at: i64, id: &str, filter: &str) -> String {
    encode_raw(&format!("{at}/{id}"), filter)
}

/// The `(created_at, id)` a token stands for.
pub fn decode_position(token: &str, filter: &str) -> Result<(i64, String), &'static str> {
    let pos = decode_raw(token, filter)?;
    let (at, id) = pos.split_once('/').ok_or(NOT_OURS)?;
    Ok((at.parse().map_err(|_| NOT_OURS)?, id.to_string()))
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
