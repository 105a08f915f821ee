//! Who may use the network views: the token a view requires when it is served beyond loopback,
//! and the caps every connection passes at accept ([`crate::gate`]).
//!
//! The views carry people's positions and the map, so a bind beyond loopback (the rig's WiFi)
//! without a token is refused at start. With a token configured every request must present it,
//! on loopback too: as `?token=` in the URL (what a person types, and what Foxglove passes in
//! `ws://rig:8765/?token=`), as `Authorization: Bearer`, or as the `starc_view_token` cookie the
//! page sets so that its own requests (the stream, the status) carry it.

use crate::error::ViewError;
use crate::gate::ConnLimits;
use crate::request::{MAX_TOKEN_BYTES, MIN_TOKEN_BYTES};
use serde::{Deserialize, Serialize, Serializer};
use std::net::{IpAddr, SocketAddr};

/// A shared secret for the network views: `MIN_TOKEN_BYTES` to `MAX_TOKEN_BYTES` of letters,
/// digits and `-._~`, the characters a URL carries as they are (so a query parameter never needs
/// decoding to be compared). Its `Debug` does not show it.
#[derive(Clone, PartialEq, Eq, Deserialize)]
#[serde(try_from = "String")]
pub struct ViewToken(String);

impl ViewToken {
    pub fn new(token: impl Into<String>) -> Result<Self, ViewError> {
        let token = token.into();
        let n = token.len();
        if !(MIN_TOKEN_BYTES..=MAX_TOKEN_BYTES).contains(&n) {
            return Err(ViewError::Config(format!(
                "token: {n} characters; it must be {MIN_TOKEN_BYTES} to {MAX_TOKEN_BYTES} (e.g. `openssl rand -hex 16`)"
            )));
        }
        if !token.bytes().all(|b| b.is_ascii_alphanumeric() || b"-._~".contains(&b)) {
            return Err(ViewError::Config("token: only letters, digits and -._~ are allowed".into()));
        }
        Ok(Self(token))
    }

    /// Whether `offered` is this token. The time taken depends on the lengths only, not on
    /// where the first difference is, so the token cannot be guessed a character at a time.
    pub fn matches(&self, offered: &str) -> bool {
        let (a, b) = (self.0.as_bytes(), offered.as_bytes());
        a.len() == b.len() && a.iter().zip(b).fold(0u8, |diff, (x, y)| diff | (x ^ y)) == 0
    }

    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl TryFrom<String> for ViewToken {
    type Error = ViewError;
    fn try_from(token: String) -> Result<Self, ViewError> {
        Self::new(token)
    }
}

impl Serialize for ViewToken {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.0)
    }
}

impl std::fmt::Debug for ViewToken {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ViewToken(..)")
    }
}

/// What a network view enforces: the connection caps and, if set, the token.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ViewAccess {
    pub limits: ConnLimits,
    pub token: Option<ViewToken>,
}

/// How a request's token compares with the configured one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Verdict {
    Allowed,
    /// No token offered (401).
    Missing,
    /// A token offered that is not ours (403).
    Wrong,
}

impl ViewAccess {
    pub(crate) fn verdict(&self, offered: Option<&str>) -> Verdict {
        match (&self.token, offered) {
            (None, _) => Verdict::Allowed,
            (Some(_), None) => Verdict::Missing,
            (Some(t), Some(o)) if t.matches(o) => Verdict::Allowed,
            (Some(_), Some(_)) => Verdict::Wrong,
        }
    }

    /// Refuses a bind beyond loopback without a token; `key` names the config key the address
    /// came from, so the error says what to change.
    pub fn check_bind(&self, key: &str, bind: SocketAddr) -> Result<(), ViewError> {
        if self.token.is_none() && !is_loopback(bind.ip()) {
            return Err(ViewError::Config(format!(
                "{key} = \"{bind}\" serves beyond this machine, which needs `token` set in [view] (a shared secret \
                 of {MIN_TOKEN_BYTES} to {MAX_TOKEN_BYTES} letters, digits or -._~ that every viewer must present); \
                 or bind 127.0.0.1"
            )));
        }
        Ok(())
    }
}

/// 127.0.0.0/8 and ::1, also written as an IPv4-mapped IPv6 address. The unspecified address
/// (0.0.0.0, ::) is every interface, so not loopback.
pub fn is_loopback(ip: IpAddr) -> bool {
    ip.to_canonical().is_loopback()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_are_checked_compared_whole_and_never_printed() {
        assert!(ViewToken::new("short").is_err());
        assert!(ViewToken::new("0123456789abcdef/").is_err(), "a slash would need URL encoding");
        assert!(ViewToken::new("x".repeat(MAX_TOKEN_BYTES + 1)).is_err());
        let t = ViewToken::new("0123456789abcdef").map_err(|e| e.to_string());
        let Ok(t) = t else { panic!("{t:?}") };
        assert!(t.matches("0123456789abcdef"));
        assert!(!t.matches("0123456789abcdeF") && !t.matches("0123456789abcde") && !t.matches(""));
        assert!(!format!("{t:?}").contains("0123"));
        let access = ViewAccess { token: Some(t), ..ViewAccess::default() };
        assert_eq!(access.verdict(None), Verdict::Missing);
        assert_eq!(access.verdict(Some("nope")), Verdict::Wrong);
        assert_eq!(access.verdict(Some("0123456789abcdef")), Verdict::Allowed);
        assert_eq!(ViewAccess::default().verdict(None), Verdict::Allowed);
    }

    #[test]
    fn only_loopback_goes_without_a_token() {
        let open = ViewAccess::default();
        for ok in ["127.0.0.1:8080", "127.9.9.9:1", "[::1]:8765", "[::ffff:127.0.0.1]:80"] {
            assert!(open.check_bind("http_bind", ok.parse().unwrap_or_else(|e| panic!("{e}"))).is_ok(), "{ok}");
        }
        for bad in ["0.0.0.0:8080", "[::]:8765", "192.168.1.20:8080", "[::ffff:10.0.0.1]:80"] {
            let e = open.check_bind("foxglove_bind", bad.parse().unwrap_or_else(|e| panic!("{e}")));
            let text = e.map(|_| String::new()).unwrap_or_else(|e| e.to_string());
            assert!(text.contains("foxglove_bind") && text.contains("`token`"), "{bad}: {text}");
        }
    }
}
