#!/usr/bin/env python3
"""A balancer for the `sweep --spread` tests: each request goes to the
replica that its X-Raysweep-Shard header hashes to (crc32 mod the number
of replicas), answers streamed back.
Usage: shard_lb.py PORT_FILE REPLICA_PORT... (writes its port to PORT_FILE)."""
import http.client, http.server, socketserver, sys, zlib
ports = [int(p) for p in sys.argv[2:]]
class H(http.server.BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"
    def log_message(self, *a): pass
    def relay(self):
        key = self.headers.get("X-Raysweep-Shard", "")
        port = ports[zlib.crc32(key.encode()) % len(ports)]
        n = int(self.headers.get("Content-Length") or 0)
        body = self.rfile.read(n) if n else None
        hop = {"connection", "keep-alive", "transfer-encoding", "host"}
        hdr = {k: v for k, v in self.headers.items() if k.lower() not in hop}
        c = http.client.HTTPConnection("127.0.0.1", port, timeout=600)
        c.request(self.command, self.path, body=body, headers=hdr)
        r = c.getresponse()
        self.send_response(r.status)
        chunked = r.getheader("Content-Length") is None
        for k, v in r.getheaders():
            if k.lower() not in hop:
                self.send_header(k, v)
        if chunked:
            self.send_header("Transfer-Encoding", "chunked")
        self.end_headers()
        while True:
            b = r.read1(65536) if chunked else r.read()
            if not b:
                break
            if chunked:
                self.wfile.write(b"%x\r\n%s\r\n" % (len(b), b))
                self.wfile.flush()
            else:
                self.wfile.write(b)
                break
        if chunked:
            self.wfile.write(b"0\r\n\r\n")
        c.close()
    do_GET = do_POST = do_PUT = do_PATCH = do_DELETE = do_HEAD = relay
class S(socketserver.ThreadingMixIn, http.server.HTTPServer):
    daemon_threads = True
s = S(("127.0.0.1", 0), H)
open(sys.argv[1], "w").write(str(s.server_address[1]))
s.serve_forever()
