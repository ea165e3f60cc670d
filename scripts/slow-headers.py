#!/usr/bin/env python3
"""Slow-header flood against a running radcast-server (docs/RELIABILITY.md).

Opens SOCKETS connections spread over ADDRESSES loopback source addresses, each sending a
partial request head and then one byte a second. Reports how many the server refused at once,
how many it closed on its header timeout, whether /healthz answered from another address
during the flood, and the server's resident memory before, at the peak and after.

Usage: scripts/slow-headers.py PORT SERVER_PID [SOCKETS] [ADDRESSES]
"""
import asyncio, http.client, sys, time

def rss_mib(pid):
    for line in open(f"/proc/{pid}/status"):
        if line.startswith("VmRSS"):
            return int(line.split()[1]) / 1024

async def slow(port, source, outcome):
    try:
        reader, writer = await asyncio.open_connection("127.0.0.1", port, local_addr=(source, 0))
    except OSError:
        outcome["connect_failed"] += 1
        return
    writer.write(b"GET /healthz HTTP/1.1\r\nHost: x\r\n")
    try:
        while True:
            first = await asyncio.wait_for(reader.read(64), 1.0)
            kind = "refused" if first.startswith(b"HTTP/1.1 4") or first.startswith(b"HTTP/1.1 5") else "closed"
            outcome[kind] += 1
            break
    except asyncio.TimeoutError:
        # Still open: trickle one more header byte a second until the server closes it.
        while True:
            try:
                writer.write(b"X")
                await writer.drain()
                data = await asyncio.wait_for(reader.read(64), 1.0)
                outcome["closed"] += 1
                break
            except asyncio.TimeoutError:
                continue
            except OSError:
                outcome["closed"] += 1
                break
    except OSError:
        outcome["closed"] += 1
    writer.close()

def healthz(port):
    """GET /healthz from an address the flood does not use."""
    try:
        start = time.monotonic()
        connection = http.client.HTTPConnection("127.0.0.1", port, timeout=5, source_address=("127.0.0.2", 0))
        connection.request("GET", "/healthz")
        status = connection.getresponse().status
        return f"{status} in {(time.monotonic() - start) * 1e3:.0f} ms"
    except Exception as e:
        return f"failed: {e}"

async def main():
    port, pid = int(sys.argv[1]), int(sys.argv[2])
    sockets = int(sys.argv[3]) if len(sys.argv) > 3 else 20000
    addresses = int(sys.argv[4]) if len(sys.argv) > 4 else 40
    outcome = {"refused": 0, "closed": 0, "connect_failed": 0}
    before = rss_mib(pid)
    started = time.monotonic()
    tasks = [asyncio.create_task(slow(port, f"127.0.1.{1 + i % addresses}", outcome)) for i in range(sockets)]
    await asyncio.sleep(3)
    peak = rss_mib(pid)
    during = await asyncio.to_thread(healthz, port)
    await asyncio.gather(*tasks)
    took = time.monotonic() - started
    await asyncio.sleep(2)
    after = rss_mib(pid)
    print(f"| {sockets} | {addresses} | {outcome['refused']} | {outcome['closed']} | {outcome['connect_failed']} "
          f"| {during} | {took:.1f} | {before:.0f} | {peak:.0f} | {after:.0f} |")

asyncio.run(main())
