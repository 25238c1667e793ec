"""meshcat's viewer window, closing the socket it replaces (meshcat 0.3.2 connects twice and
leaves the first socket to the garbage collector, which warns about it)."""

from __future__ import annotations

import meshcat.visualizer


class Window(meshcat.visualizer.ViewerWindow):  # type: ignore[misc]
    def connect_zmq(self) -> None:
        old = getattr(self, "zmq_socket", None)
        if old is not None:
            old.close(linger=0)
        super().connect_zmq()
