"""The emulators' own counts against the firmware's: QEMU's single steps, one instruction each.

On the Cortex-M the firmware counts a step by a timer that QEMU clocks by its instruction
counter (``-icount``). Here QEMU's GDB stub counts the same step another way: a
breakpoint where the controller's step begins, then one instruction at a time until it
returns. The two counts agree to the instructions of the call itself.
"""

from __future__ import annotations

import re
import socket
import subprocess
import time

import numpy as np
import pytest

from equilibrist.cli.main import build_parser
from equilibrist.cli.simulate import build_run
from equilibrist.hil import protocol as proto
from equilibrist.hil.link import SerialLink
from equilibrist.pil.emulator import emulate
from equilibrist.pil.run import firmware_for
from equilibrist.pil.targets import get
from support import require


class Remote:
    """The few packets of GDB's remote serial protocol that stop, step and read a program."""

    def __init__(self, port: int) -> None:
        deadline = time.monotonic() + 20
        while True:
            try:
                self.sock = socket.create_connection(("127.0.0.1", port), timeout=60)
                self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)
        self.buf = b""

    def packet(self) -> str:
        while True:
            found = re.search(rb"\$([^#]*)#[0-9a-fA-F]{2}", self.buf)
            if found:
                self.buf = self.buf[found.end():]
                self.sock.sendall(b"+")
                return found.group(1).decode()
            data = self.sock.recv(4096)
            assert data, "QEMU's GDB stub closed"
            self.buf += data

    def send(self, text: str) -> None:
        body = text.encode()
        self.sock.sendall(b"$" + body + b"#%02x" % (sum(body) & 0xFF))

    def ask(self, text: str) -> str:
        self.send(text)
        return self.packet()

    def register(self, n: int) -> int:
        regs = self.ask("g")
        return int.from_bytes(bytes.fromhex(regs[8 * n: 8 * n + 8]), "little")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.mark.slow
@pytest.mark.parametrize("chip", ["cortex-m4f", "cortex-m0"])
def test_the_firmwares_count_is_qemus_instruction_count(chip: str) -> None:
    """The Cortex-M4F reads a timer at 1 GHz of QEMU's virtual clock (one tick an instruction
    under -icount shift=0), the Cortex-M0 the nRF51's 16 MHz timer (2.048 ticks an
    instruction under shift=7): both say how many instructions QEMU stepped."""
    target = get(chip)
    for tool, _ in target.tools:
        require(tool)
    require("arm-none-eabi-nm")
    args = build_parser("pil").parse_args(["pil", "cartpole", "--controller", "lqr",
                                           "--target", chip])
    system, options = build_run(args)
    firmware = firmware_for(options["controller"], system=system, target=target,
                            precision="float", label="lqr")
    symbols = subprocess.run(["arm-none-eabi-nm", str(firmware.elf)], capture_output=True,
                             text=True, check=True).stdout
    entry = int(re.search(r"^([0-9a-f]+) T hil_ctrl_step$", symbols, re.M).group(1), 16)  # type: ignore[union-attr]
    port = _free_port()
    with emulate(firmware, extra=("-gdb", f"tcp:127.0.0.1:{port}", "-S")) as emulation:
        gdb = Remote(port)
        gdb.ask("?")
        gdb.send("c")
        y = np.array([0.01, 0.1, -0.02, 0.3])
        with SerialLink(emulation.port) as link:
            hello = proto.Hello(real_size=4, n=4, m=1, p=4, references=0, estimate=0,
                                rate=200.0, controller_id="")
            _ask(link, proto.HELLO, hello.pack(), proto.HELLO_REPLY, tries=20)
            step = proto.step_payload(y, np.zeros(0), 4)
            first = _ask(link, proto.STEP, step, proto.STEP_REPLY)
            gdb.sock.sendall(b"\x03")  # stop the program, to set the breakpoint
            gdb.packet()
            assert gdb.ask(f"Z1,{entry:x},2") == "OK"
            gdb.send("c")
            link.send(proto.STEP, 7, step)  # the same sample again: the same instructions
            gdb.packet()  # the breakpoint
            assert gdb.ask(f"z1,{entry:x},2") == "OK"
            back = gdb.register(14) & ~1
            stepped = 0
            while True:
                gdb.ask("s")
                stepped += 1
                if gdb.register(15) == back:
                    break
            gdb.send("c")
            second = _receive(link, proto.STEP_REPLY)
            gdb.sock.close()
        assert first[:-4] == second[:-4]  # an LQR has no state: the same answer (but its time)
    counts = [s.count for s in emulation.steps]  # all read once the emulator has ended
    # The firmware's count of the first step (as pil reads it: instructions from the timer's
    # ticks); the stepped one is the controller's instructions to its return: the call's
    # branch is the instruction more the firmware counts.
    assert counts, "the firmware reported no step"
    assert 100 < stepped < 10_000
    assert abs(counts[0] - stepped) <= 2


def _ask(link: SerialLink, kind: int, payload: bytes, answer: int, tries: int = 1) -> bytes:
    for seq in range(1, tries + 1):
        link.send(kind, seq, payload)
        try:
            return _receive(link, answer, wait=1.0 if tries > 1 else 10.0)
        except AssertionError:
            if seq == tries:
                raise
    raise AssertionError("unreachable")


def _receive(link: SerialLink, answer: int, wait: float = 10.0) -> bytes:
    deadline = time.perf_counter() + wait
    while True:
        f = link.receive(deadline)
        assert f is not None, "no answer from the firmware"
        if f.kind == answer:
            return f.payload
