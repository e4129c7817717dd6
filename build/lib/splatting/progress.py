"""One progress line for long work, on stderr: rewritten in place on a terminal, one line every
`every_s` seconds otherwise (logs and CI stay readable)."""
import sys
import time


class Progress:
    def __init__(self, enabled=True, tty_every_s=0.5, log_every_s=15.0, stream=None):
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.tty = enabled and self.stream.isatty()
        self.every = tty_every_s if self.tty else log_every_s
        self.last = 0.0

    def line(self, text, force=False):
        """Show `text` unless the last line was shown less than the period ago (force: always)."""
        if not self.enabled:
            return
        now = time.time()
        if not force and now - self.last < self.every:
            return
        self.last = now
        self.stream.write(("\r" + text) if self.tty else text + "\n")
        self.stream.flush()

    def close(self):
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()
