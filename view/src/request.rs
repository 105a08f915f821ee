//! Sans-IO parsing of an HTTP/1.x request head, as much as the live view needs: the method and
//! the path of a GET or HEAD, and the access token it offers (query, `Authorization: Bearer` or
//! cookie; the Foxglove server takes it from the WebSocket upgrade the same way). Bytes come from any browser on the network, so every length is
//! capped and nothing here can panic. Std only, so the fuzz target can include this file as is.

/// The largest request head accepted (request line and headers, blank line included).
pub const MAX_HEAD_BYTES: usize = 8 * 1024;
/// The longest request path accepted.
pub const MAX_PATH_BYTES: usize = 1024;
/// The shortest access token a config may set.
pub const MIN_TOKEN_BYTES: usize = 16;
/// The longest access token a config may set; a longer one offered cannot match and is dropped.
pub const MAX_TOKEN_BYTES: usize = 256;
/// The query parameter that carries the token: `/?token=...`, `ws://rig:8765/?token=...`.
pub const TOKEN_PARAM: &str = "token";
/// The cookie the page sets so that its own requests (stream, status) carry the token.
pub const TOKEN_COOKIE: &str = "starc_view_token";

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    Get,
    Head,
}

/// A request the server can answer.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Request {
    pub method: Method,
    /// The path without its query string, e.g. `/frame.png`.
    pub path: String,
    /// The access token offered, if any ([`offered_token`]).
    pub token: Option<String>,
}

/// Why a request head was refused, with the status it is answered with.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RequestError {
    /// No blank line within [`MAX_HEAD_BYTES`] (431).
    TooLarge,
    /// Not an HTTP/1.x request line, or a header line without a colon (400).
    Malformed(&'static str),
    /// A method other than GET and HEAD (405).
    MethodNotAllowed,
}

impl RequestError {
    pub fn status(&self) -> (u16, &'static str) {
        match self {
            RequestError::TooLarge => (431, "Request Header Fields Too Large"),
            RequestError::Malformed(_) => (400, "Bad Request"),
            RequestError::MethodNotAllowed => (405, "Method Not Allowed"),
        }
    }
}

/// Where the head ends (the index just past `\r\n\r\n`), if it is in `buf`; `Err(TooLarge)`
/// once `buf` holds [`MAX_HEAD_BYTES`] without one.
pub fn head_end(buf: &[u8]) -> Result<Option<usize>, RequestError> {
    let searched = &buf[..buf.len().min(MAX_HEAD_BYTES)];
    if let Some(i) = searched.windows(4).position(|w| w == b"\r\n\r\n") {
        return Ok(Some(i + 4));
    }
    if buf.len() >= MAX_HEAD_BYTES {
        return Err(RequestError::TooLarge);
    }
    Ok(None)
}

/// Parses a complete head (as delimited by [`head_end`]).
pub fn parse_head(head: &[u8]) -> Result<Request, RequestError> {
    if head.len() > MAX_HEAD_BYTES {
        return Err(RequestError::TooLarge);
    }
    let text = std::str::from_utf8(head).map_err(|_| RequestError::Malformed("not UTF-8"))?;
    let mut lines = text.split("\r\n");
    let request_line = lines.next().unwrap_or_default();
    let mut parts = request_line.split(' ');
    let (Some(method), Some(target), Some(version), None) = (parts.next(), parts.next(), parts.next(), parts.next())
    else {
        return Err(RequestError::Malformed("request line is not METHOD TARGET VERSION"));
    };
    if version != "HTTP/1.1" && version != "HTTP/1.0" {
        return Err(RequestError::Malformed("not HTTP/1.0 or HTTP/1.1"));
    }
    let (mut authorization, mut cookie) = (None, None);
    for line in lines.take_while(|l| !l.is_empty()) {
        let Some((name, value)) = line.split_once(':') else {
            return Err(RequestError::Malformed("header line without a colon"));
        };
        if name.is_empty() || name.bytes().any(|b| !(b.is_ascii_graphic())) {
            return Err(RequestError::Malformed("bad header name"));
        }
        // The first of each counts; a repeat cannot smuggle in a second opinion.
        if name.eq_ignore_ascii_case("authorization") && authorization.is_none() {
            authorization = Some(value.trim());
        } else if name.eq_ignore_ascii_case("cookie") && cookie.is_none() {
            cookie = Some(value.trim());
        }
    }
    let method = match method {
        "GET" => Method::Get,
        "HEAD" => Method::Head,
        m if !m.is_empty() && m.bytes().all(|b| b.is_ascii_uppercase()) => return Err(RequestError::MethodNotAllowed),
        _ => return Err(RequestError::Malformed("bad method")),
    };
    if !target.starts_with('/') || target.len() > MAX_PATH_BYTES {
        return Err(RequestError::Malformed("target is not an absolute path"));
    }
    let without_fragment = target.split('#').next().unwrap_or_default();
    let (path, query) = match without_fragment.split_once('?') {
        Some((path, query)) => (path, Some(query)),
        None => (without_fragment, None),
    };
    if path.bytes().any(|b| !b.is_ascii_graphic()) {
        return Err(RequestError::Malformed("bad path"));
    }
    let token = offered_token(query, authorization, cookie).map(str::to_string);
    Ok(Request { method, path: path.to_string(), token })
}

/// The token a request offers, from the first place that has one: the `token` query parameter,
/// an `Authorization: Bearer` header, the [`TOKEN_COOKIE`] cookie. Taken as written (tokens are
/// URL-safe, so nothing is decoded); one longer than [`MAX_TOKEN_BYTES`] counts as none offered.
pub fn offered_token<'a>(
    query: Option<&'a str>,
    authorization: Option<&'a str>,
    cookie: Option<&'a str>,
) -> Option<&'a str> {
    let from_query = query.and_then(|q| q.split('&').find_map(|kv| kv.strip_prefix(TOKEN_PARAM)?.strip_prefix('=')));
    let from_header = authorization.and_then(|a| {
        let (scheme, value) = a.trim().split_once(' ')?;
        scheme.eq_ignore_ascii_case("bearer").then(|| value.trim())
    });
    let from_cookie =
        cookie.and_then(|c| c.split(';').find_map(|kv| kv.trim().strip_prefix(TOKEN_COOKIE)?.strip_prefix('=')));
    from_query.or(from_header).or(from_cookie).filter(|t| !t.is_empty() && t.len() <= MAX_TOKEN_BYTES)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_get_and_head_and_strips_the_query() {
        let r = parse_head(b"GET /frame.png?t=12 HTTP/1.1\r\nHost: rig:8080\r\n\r\n");
        assert_eq!(r, Ok(Request { method: Method::Get, path: "/frame.png".into(), token: None }));
        let r = parse_head(b"HEAD / HTTP/1.0\r\n\r\n");
        assert_eq!(r, Ok(Request { method: Method::Head, path: "/".into(), token: None }));
    }

    #[test]
    fn finds_the_token_in_the_query_the_bearer_header_or_the_cookie() {
        let token = |head: &[u8]| parse_head(head).map(|r| r.token);
        assert_eq!(token(b"GET /?a=1&token=abc&b=2 HTTP/1.1\r\n\r\n"), Ok(Some("abc".into())));
        assert_eq!(token(b"GET /stream HTTP/1.1\r\nauthorization: bearer xyz\r\n\r\n"), Ok(Some("xyz".into())));
        assert_eq!(token(b"GET / HTTP/1.1\r\nCookie: a=b; starc_view_token=ck\r\n\r\n"), Ok(Some("ck".into())));
        // The query wins over the cookie (a new link replaces an old cookie); Basic is not a token.
        assert_eq!(token(b"GET /?token=q HTTP/1.1\r\nCookie: starc_view_token=ck\r\n\r\n"), Ok(Some("q".into())));
        assert_eq!(token(b"GET / HTTP/1.1\r\nAuthorization: Basic eDp5\r\n\r\n"), Ok(None));
        assert_eq!(token(b"GET /?tokenx=1&token= HTTP/1.1\r\n\r\n"), Ok(None));
        let long = format!("GET /?token={} HTTP/1.1\r\n\r\n", "a".repeat(MAX_TOKEN_BYTES + 1));
        assert_eq!(token(long.as_bytes()), Ok(None));
    }

    #[test]
    fn refuses_what_it_cannot_answer() {
        assert_eq!(parse_head(b"POST / HTTP/1.1\r\n\r\n"), Err(RequestError::MethodNotAllowed));
        assert!(matches!(parse_head(b"GET / HTTP/2\r\n\r\n"), Err(RequestError::Malformed(_))));
        assert!(matches!(parse_head(b"GET relative HTTP/1.1\r\n\r\n"), Err(RequestError::Malformed(_))));
        assert!(matches!(parse_head(b"GET / HTTP/1.1\r\nno colon\r\n\r\n"), Err(RequestError::Malformed(_))));
        assert!(matches!(parse_head(b"\xff\xfe\r\n\r\n"), Err(RequestError::Malformed(_))));
        assert!(matches!(parse_head(b""), Err(RequestError::Malformed(_))));
    }

    #[test]
    fn finds_the_end_of_the_head_or_gives_up_at_the_cap() {
        assert_eq!(head_end(b"GET / HTTP/1.1\r\n"), Ok(None));
        assert_eq!(head_end(b"GET / HTTP/1.1\r\n\r\nbody"), Ok(Some(18)));
        assert_eq!(head_end(&vec![b'a'; MAX_HEAD_BYTES]), Err(RequestError::TooLarge));
    }
}
