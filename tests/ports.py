"""Serial ports for driver tests: one replays recorded command/response pairs (PyMeasure's way of testing drivers
without hardware), one talks to a simulated generator in this process."""

from instruments.simulator.generator import GeneratorDevice


class ReplayPort:
    """A serial port that expects ``exchanges`` in order: (line sent, reply bytes or None)."""

    port = "replay"

    def __init__(self, exchanges):
        self.exchanges = list(exchanges)
        self.pending = b""

    def write(self, data: bytes) -> int:
        assert self.exchanges, f"unexpected write {data!r}"
        sent, reply = self.exchanges.pop(0)
        assert data == sent.encode() + b"\n"
        self.pending += reply or b""
        return len(data)

    def read_until(self, terminator=b"\n"):
        line, found, rest = self.pending.partition(terminator)
        self.pending = rest
        return line + found

    def read(self, size=1):
        head, self.pending = self.pending[:size], self.pending[size:]
        return head

    def reset_input_buffer(self):
        self.pending = b""

    def done(self) -> bool:
        return not self.exchanges


class DevicePort:
    """A serial port onto a simulated generator in this process (its state can be changed behind the driver)."""

    port = "device"

    def __init__(self, device: GeneratorDevice):
        self.device = device
        self.pending = b""

    def write(self, data: bytes) -> int:
        for line in data.decode().split("\n")[:-1]:
            reply = self.device.handle_line(line)
            if reply is not None:
                self.pending += reply.encode() + b"\n"
        return len(data)

    def read_until(self, terminator=b"\n"):
        line, found, self.pending = self.pending.partition(terminator)
        return line + found

    def reset_input_buffer(self):
        self.pending = b""
