#!/usr/bin/env python3
"""End-to-end test of the Python pipeline client (client/python/cloudbake_client.py) against a
real cloudbake-server on loopback. Usage: python_client_test.py SERVER_BIN STUBS_DIR CLIENT_DIR.
Exits 77 (ctest: skipped) when python3-grpcio is not installed."""

import hashlib
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time

try:
    import grpc
except ImportError:
    print("SKIP: python3-grpcio is not installed (apt-get install python3-grpcio)")
    sys.exit(77)

SERVER_BIN, STUBS, CLIENT_DIR = sys.argv[1:4]
sys.path[:0] = [STUBS, CLIENT_DIR]
import cloudbake_client  # noqa: E402
from cloudbake.v1 import bake_service_pb2 as pb  # noqa: E402

SHOT = {
    "version": 1, "name": "py",
    "volume": {"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}},
    "medium": {"extinction": 2, "albedo": 0.9, "phase": {"type": "hg", "g": 0.5}},
    "lighting": {"sun": {"direction": [0, 0, 1], "irradiance": [1, 1, 1]}},
    "bake": {"method": "pathtrace", "samples": 4, "seed": 1},
    "views": [{"name": "front", "camera": {"type": "orthographic", "position": [0, -5, 0],
                                           "look_at": [0, 0, 0], "up": [0, 0, 1], "width": 2.5},
               "resolution": [16, 16]}],
    "outputs": {"exr": True, "vdb": True, "vdb_voxel_size": 0.1},
}


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def stop(server, work):
    """SIGTERM, a kill after 10 s, and the work folder removed."""
    server.terminate()
    try:
        server.wait(timeout=10)
    except subprocess.TimeoutExpired:
        server.kill()
    shutil.rmtree(work, ignore_errors=True)


def check(cond, what):
    if not cond:
        raise AssertionError(what)
    print("ok:", what)


def main():
    work = tempfile.mkdtemp(prefix="cloudbake_py_")
    address = "127.0.0.1:%d" % free_port()
    server = subprocess.Popen([SERVER_BIN, "--listen", address, "--cache-dir",
                               os.path.join(work, "state"), "--threads", "2",
                               "--log-level", "warn"])
    try:
        client = cloudbake_client.BakeClient(address, timeout=15)
        check("pathtrace" in client.info().methods, "server info lists pathtrace")

        shot_path = os.path.join(work, "shot", "sphere.json")
        os.makedirs(os.path.dirname(shot_path))
        with open(shot_path, "w") as f:
            json.dump(SHOT, f)
        events = []
        job = client.submit_file(shot_path)
        job = client.wait(job.id, on_event=events.append)
        check(job.state == pb.SUCCEEDED, "job succeeded (%s)" % job.error)
        check(len(events) >= 3 and events[-1].HasField("job"), "progress events streamed")
        paths = client.fetch_all(job, os.path.join(work, "out"))
        check(sorted(os.path.basename(p) for p in paths) == ["bake.vdb", "front.exr"],
              "fetched DIR/front.exr and DIR/bake.vdb")
        with open(os.path.join(work, "out", "front.exr"), "rb") as f:
            check(f.read(4) == b"\x76\x2f\x31\x01", "front.exr starts with the OpenEXR magic")

        # Chunked streaming: 64 KiB chunks, in order, each with total size and checksum.
        vdb = [o for o in job.outputs if o.name == "bake.vdb"][0]
        chunks = list(client.stub.FetchResult(pb.FetchResultRequest(
            job_id=job.id, name="bake.vdb", chunk_size=65536)))
        check(len(chunks) == (vdb.size + 65535) // 65536 and len(chunks) >= 2,
              "bake.vdb (%d bytes) came in %d chunks of 64 KiB" % (vdb.size, len(chunks)))
        check(all(c.total_size == vdb.size and c.sha256 == vdb.sha256 for c in chunks)
              and [c.offset for c in chunks] == [i * 65536 for i in range(len(chunks))],
              "every chunk carries offset, total size and SHA-256")
        tail = list(client.stub.FetchResult(pb.FetchResultRequest(
            job_id=job.id, name="bake.vdb", offset=vdb.size - 10)))
        check(len(tail) == 1 and len(tail[0].data) == 10, "fetch resumes from an offset")
        try:
            list(client.stub.FetchResult(pb.FetchResultRequest(
                job_id=job.id, name="bake.vdb", chunk_size=100)))
            check(False, "tiny chunk size rejected")
        except grpc.RpcError as e:
            check(e.code() == grpc.StatusCode.INVALID_ARGUMENT and "chunk_size" in e.details(),
                  "chunk_size outside 64 KiB..1 MiB -> INVALID_ARGUMENT")

        # A shot naming a file: the client uploads it; the same content is not sent twice.
        os.makedirs(os.path.join(work, "shot", "assets"))
        shutil.copy(os.path.join(work, "out", "bake.vdb"),
                    os.path.join(work, "shot", "assets", "cloud.vdb"))
        vdb_shot = dict(SHOT, name="py_vdb", volume={"vdb": {"path": "assets/cloud.vdb"}},
                        outputs={"exr": True, "vdb": False})
        job2 = client.wait(client.submit(json.dumps(vdb_shot),
                                         base_dir=os.path.join(work, "shot")).id)
        check(job2.state == pb.SUCCEEDED, "VDB shot with an uploaded asset succeeded (%s)"
              % job2.error)
        digest = cloudbake_client.sha256_file(os.path.join(work, "shot", "assets", "cloud.vdb"))
        reply = client.stub.UploadAsset(iter([pb.UploadAssetRequest(
            header=pb.AssetHeader(sha256=digest, size=1))]))
        check(reply.already_present, "a second upload of the same content is not needed")

        for label, header, data in [
                ("wrong checksum", pb.AssetHeader(sha256="0" * 64, size=5), b"hello"),
                ("truncated upload", pb.AssetHeader(
                    sha256=hashlib.sha256(b"abcdef").hexdigest(), size=6), b"abc"),
                ("bad hash text", pb.AssetHeader(sha256="xyz", size=3), b"abc")]:
            try:
                client.stub.UploadAsset(iter([pb.UploadAssetRequest(header=header),
                                              pb.UploadAssetRequest(data=data)]))
                check(False, label + " rejected")
            except grpc.RpcError as e:
                check(e.code() == grpc.StatusCode.INVALID_ARGUMENT,
                      "%s -> INVALID_ARGUMENT (%s)" % (label, e.details()))
        # Outside probe: "..a.vdb" is a file of the folder (it was never uploaded), and a link
        # leading outside the folder is refused unless asked for (it was uploaded silently).
        shutil.copy(os.path.join(work, "shot", "assets", "cloud.vdb"),
                    os.path.join(work, "shot", "..a.vdb"))
        dots = dict(vdb_shot, name="py_dots", volume={"vdb": {"path": "..a.vdb"}})
        job_dots = client.wait(client.submit(json.dumps(dots), base_dir=os.path.join(work, "shot")).id)
        check(job_dots.state == pb.SUCCEEDED, "a file named ..a.vdb is uploaded (%s)" % job_dots.error)
        os.makedirs(os.path.join(work, "outside"))
        shutil.copy(os.path.join(work, "shot", "assets", "cloud.vdb"),
                    os.path.join(work, "outside", "secret.vdb"))
        os.symlink(os.path.join(work, "outside", "secret.vdb"),
                   os.path.join(work, "shot", "link.vdb"))
        linked = dict(vdb_shot, name="py_link", volume={"vdb": {"path": "link.vdb"}})
        def refused(shot, needle, what):
            """A submit the client refuses before any upload, saying `needle`."""
            try:
                client.submit(json.dumps(shot), base_dir=os.path.join(work, "shot"))
                check(False, what)
            except ValueError as e:
                check(needle in str(e), "%s (%s)" % (what, e))

        refused(linked, "leads outside the shot's folder",
                "a link leading outside the shot's folder is refused")
        job_link = client.wait(client.submit(json.dumps(linked), base_dir=os.path.join(work, "shot"),
                                             allow_outside=True).id)
        check(job_link.state == pb.SUCCEEDED, "allow_outside=True uploads it")
        many = dict(vdb_shot, name="py_many",
                    volume={"sequence": {"paths": ["f%d.vdb" % i for i in range(4097)]}})
        refused(many, "4097 files, more than the 4096",
                "a shot naming 4097 files is refused before any is read")
        try:
            cloudbake_client.BakeClient("127.0.0.1:%d" % free_port(), timeout=0.5)
            check(False, "a server that is down is a clear error")
        except ConnectionError as e:
            check("cannot reach cloudbake-server" in str(e), "a server that is down: %s" % e)
        try:
            client.submit('{"version": 1, "name": ')
            check(False, "malformed shot rejected")
        except grpc.RpcError as e:
            check(e.code() == grpc.StatusCode.INVALID_ARGUMENT and "shot.json" in e.details(),
                  "malformed shot -> INVALID_ARGUMENT naming shot.json (%s)" % e.details())
        # RenderView: a new sun colour of the first job, from the cache.
        job3 = client.wait(client.render(job.id, sun_irradiance=[2, 2, 2]).id)
        check(job3.state == pb.SUCCEEDED, "RenderView with a new sun colour (%s)" % job3.error)
        check([o.name for o in job3.outputs].count("front.exr") == 1, "RenderView wrote front.exr")
        # Output names that would write outside the folder are refused before any download.
        for name in ["../../x", "/etc/passwd", "..", "a/b", ""]:
            try:
                client.fetch(job.id, pb.OutputFile(name=name, size=1, sha256="0" * 64),
                             os.path.join(work, "safe"))
                check(False, "unsafe output name %r refused" % name)
            except IOError as e:
                check("unsafe output name" in str(e), "unsafe output name %r refused" % name)
        try:
            client.stub.GetJob(pb.GetJobRequest(job_id="j0000000000000000"))
            check(False, "unknown job rejected")
        except grpc.RpcError as e:
            check(e.code() == grpc.StatusCode.NOT_FOUND, "unknown job -> NOT_FOUND")
        client.close()
    finally:
        stop(server, work)
    check(server.returncode == 0, "server exited cleanly on SIGTERM")
    check_tokens()
    return 0


def check_tokens():
    """With --auth-tokens: no token is refused, each client sees only its own jobs."""
    work = tempfile.mkdtemp(prefix="cloudbake_py_tokens_")
    address = "127.0.0.1:%d" % free_port()
    tokens = os.path.join(work, "tokens.txt")
    with open(tokens, "w") as f:
        f.write("alice alice-token-0123456789\nbob bob-token-0123456789abc\n")
    server = subprocess.Popen([SERVER_BIN, "--listen", address, "--cache-dir",
                               os.path.join(work, "state"), "--threads", "2",
                               "--log-level", "warn", "--auth-tokens", tokens])
    try:
        anonymous = cloudbake_client.BakeClient(address, timeout=15, token="")
        try:
            anonymous.stub.ListJobs(pb.ListJobsRequest(), timeout=10)
            check(False, "a call without a token is refused")
        except grpc.RpcError as e:
            check(e.code() == grpc.StatusCode.UNAUTHENTICATED, "no token -> UNAUTHENTICATED")
        alice = cloudbake_client.BakeClient(address, timeout=15,
                                            token="alice-token-0123456789")
        shot_path = os.path.join(work, "sphere.json")
        with open(shot_path, "w") as f:
            json.dump(SHOT, f)
        job = alice.wait(alice.submit_file(shot_path).id)
        check(job.state == pb.SUCCEEDED, "alice's job succeeded with her token")
        token_file = os.path.join(work, "bob.token")
        with open(token_file, "w") as f:
            f.write("bob-token-0123456789abc\n")
        bob = cloudbake_client.BakeClient(address, timeout=15, token_file=token_file)
        listed = bob.stub.ListJobs(pb.ListJobsRequest(), timeout=10).jobs
        check(len(listed) == 0, "bob lists none of alice's jobs")
        try:
            bob.stub.GetJob(pb.GetJobRequest(job_id=job.id), timeout=10)
            check(False, "bob cannot read alice's job")
        except grpc.RpcError as e:
            check(e.code() == grpc.StatusCode.NOT_FOUND, "alice's job is NOT_FOUND for bob")
        for c in (anonymous, alice, bob):
            c.close()
    finally:
        stop(server, work)


if __name__ == "__main__":
    sys.exit(main())
