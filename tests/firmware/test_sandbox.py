"""The private root QEMU's check runs live in (firmware/sandbox.py): the image and the work
folder are all it sees of the host files; /usr is read-only; no network. Checked with ordinary
programs in place of QEMU (no cross toolchain needed)."""
import subprocess

import pytest

from cdam_core.firmware import sandbox

pytestmark = pytest.mark.skipif(sandbox.available() is not None,
                                reason=f"no sandbox here: {sandbox.available()}")


def _run(tmp_path, program, *args):
    elf = tmp_path / "image.elf"
    elf.write_bytes(b"not really an image")
    work = tmp_path / "work"
    work.mkdir(exist_ok=True)
    cmd, where = sandbox.sandboxed(program, list(args), elf, work)
    assert where.startswith("private root")
    return subprocess.run(cmd, capture_output=True, text=True, timeout=60), work


def test_only_usr_the_image_and_the_work_folder_are_visible(tmp_path):
    r, _ = _run(tmp_path, "ls", "/")
    assert r.returncode == 0, r.stderr
    assert set(r.stdout.split()) == {"bin", "dev", "img", "lib", "lib64", "usr", "work"}
    r, _ = _run(tmp_path, "cat", sandbox.IMAGE)
    assert r.stdout == "not really an image"
    for secret in ("/etc/passwd", str(tmp_path / "image.elf"), "/root", "/proc/self/environ"):
        r, _ = _run(tmp_path, "cat", secret)
        assert r.returncode != 0, secret


def test_writes_reach_only_the_work_folder(tmp_path):
    r, work = _run(tmp_path, "sh", "-c", "echo out > result.bin")
    assert r.returncode == 0 and (work / "result.bin").read_text() == "out\n"
    # (the private root itself is a small tmpfs: what is written there vanishes with the run)
    for target in ("/usr/cdam_probe", sandbox.IMAGE):
        r, _ = _run(tmp_path, "sh", "-c", f"echo x > {target}")
        assert r.returncode != 0, target
    assert (tmp_path / "image.elf").read_bytes() == b"not really an image"


def test_no_network(tmp_path):
    """A listening socket on the host's loopback: reachable from outside, not from inside."""
    import shutil
    import socket
    py = shutil.which("python3", path="/usr/bin")
    if py is None:
        pytest.skip("no /usr/bin/python3 to probe the network with")
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(4)
    port = srv.getsockname()[1]
    probe = f"import socket; socket.create_connection(('127.0.0.1', {port}), timeout=5)"
    try:
        assert subprocess.run([py, "-c", probe], timeout=30).returncode == 0   # outside: open
        r, _ = _run(tmp_path, py, "-c", probe)
        assert r.returncode != 0 and "Error" in r.stderr
    finally:
        srv.close()
