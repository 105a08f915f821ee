"""Reads N parts of a multipart/x-mixed-replace stream with Python's http.client, as a browser
would, for view/tests/view_http.rs. Prints JSON: the response's Content-Type and each part's
Content-Type and body (hex)."""

import http.client
import json
import sys


def main():
    host, port, path, n = sys.argv[1], int(sys.argv[2]), sys.argv[3], int(sys.argv[4])
    conn = http.client.HTTPConnection(host, port, timeout=10)
    conn.request("GET", path)
    resp = conn.getresponse()
    ctype = resp.getheader("Content-Type")
    boundary = "--" + ctype.split("boundary=", 1)[1]
    parts = []
    line = resp.fp.readline().decode().strip()
    assert line == boundary, f"expected the boundary, got {line!r}"
    while len(parts) < n:
        headers = {}
        while True:
            line = resp.fp.readline().decode().strip()
            if not line:
                break
            k, v = line.split(":", 1)
            headers[k.strip().lower()] = v.strip()
        body = resp.fp.read(int(headers["content-length"]))
        parts.append({"content_type": headers.get("content-type"), "body": body.hex()})
        rest = resp.fp.readline()  # the CRLF ending the body
        assert rest == b"\r\n", rest
        line = resp.fp.readline().decode().strip()
        assert line == boundary, f"expected the boundary, got {line!r}"
    print(json.dumps({"status": resp.status, "content_type": ctype, "parts": parts}))


if __name__ == "__main__":
    main()
