"""``gsseg view``: a run in the browser, on viser.

Frames are rendered on the server by the project's own rasterizer for each browser's camera
(as nerfview does) and sent as the scene's background image, so what the browser shows is
exactly what ``gsseg render`` and ``gsseg edit`` write, learned background included, on a
CPU-only machine as on a GPU one. viser draws the training cameras over it and reports
clicks as (u, v) on the canvas; the panel drives a :class:`~gsseg.viewer.session.ViewerSession`.
"""

from __future__ import annotations

import html
import logging
import socket
import threading
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from dataset_tools.image_files import label_palette
from dataset_tools.infra.errors import InputError, OptionError
from dataset_tools.infra.interrupts import Interrupted, stop_requests
from gsseg.fill_options import FillOptions
from gsseg.run.loaded import load_run
from gsseg.segment.label_options import METHODS
from gsseg.viewer.session import ViewCamera, ViewerSession, browser_camera

RESOLVE_TIMEOUT_S = 5.0


def resolve_host(host: str, timeout: float = RESOLVE_TIMEOUT_S) -> str:
    """The numeric address of ``host``, refused in one sentence when it does not resolve
    within ``timeout`` seconds (a name lookup on a machine without a network can hang)."""
    found: list = []
    lookup = threading.Thread(target=lambda: found.append(_lookup(host)), daemon=True)
    lookup.start()
    lookup.join(timeout)
    if not found or isinstance(found[0], OSError):
        why = f"{found[0].strerror or found[0]}" if found else f"no answer in {timeout:.0f} s"
        raise OptionError(
            f"cannot serve on {host} ({why}); pass an address of this machine as {{host}}, such as 127.0.0.1 or "
            "0.0.0.0."
        )
    return found[0]


def _lookup(host: str) -> str | OSError:
    try:
        return socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)[0][4][0]
    except (OSError, UnicodeError) as e:
        return e if isinstance(e, OSError) else OSError(str(e))


def require_free_port(host: str, port: int) -> None:
    """Refuse a host that is no address of this machine, or a port another process listens
    on (viser would silently take the next one); port 0 checks the host alone."""
    address = resolve_host(host)
    with socket.socket(socket.AF_INET6 if ":" in address else socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind((address, port))
        except OSError as e:
            raise OptionError(
                f"cannot serve on {host}:{port} ({e.strerror}); pass another {{port}} or {{host}}, or stop the "
                "program that uses it."
            ) from None


def _one_line_connection_errors(record: logging.LogRecord) -> bool:
    """A browser connection that fails (a malformed frame, a dropped socket) is one line on
    stderr, not the server library's traceback; the viewer keeps serving the others."""
    if record.exc_info and record.exc_info[1] is not None:
        error = record.exc_info[1]
        first = str(error).splitlines()[0] if str(error) else ""
        record.msg, record.args = f"warning: a browser connection ended: {type(error).__name__}: {first}", ()
        record.exc_info, record.exc_text = None, None
    return True


class Viewer:
    """A running viewer: one viser server, one session, one render thread per browser tab.

    Args:
        session: what is shown and edited.
        host, port: where to serve (port 0: any free port).
        max_size: frames are rendered at most this many pixels on their long side and
            stretched by the browser.
    """

    def __init__(
        self, session: ViewerSession, *, host: str = "127.0.0.1", port: int = 8080, max_size: int = 640
    ) -> None:
        import viser

        require_free_port(host, port)
        self.session = session
        self.max_size = max_size
        self.views = session.scene.split("train")
        logging.getLogger("websockets.server").addFilter(_one_line_connection_errors)
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.host = host
        self._dirty: dict[int, threading.Event] = {}
        self._render_lock = threading.Lock()
        self._stopped = threading.Event()
        self._filling: threading.Thread | None = None  # the thread filling the last removal
        self.server.scene.world_axes.visible = False
        self.server.gui.configure_theme(show_logo=False, show_share_button=False, control_width="medium")
        self.server.gui.main_panel.dock_right()
        self._add_cameras()
        self._add_panel()
        self.server.on_client_connect(self._connect)
        self.server.on_client_disconnect(lambda client: self._dirty.pop(client.client_id, threading.Event()).set())
        self.server.scene.on_click()(lambda event: self._click(event, "select"))
        self.server.scene.on_click(modifier="cmd/ctrl")(lambda event: self._click(event, "add"))
        self.server.scene.on_click(modifier="shift")(lambda event: self._click(event, "exclude"))

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.server.get_port()}"

    def stop(self) -> None:
        """Stop serving, once a fill in progress has finished (a thread stopped within its
        rendering would abort the process)."""
        self._stopped.set()
        for event in list(self._dirty.values()):
            event.set()
        if self._filling is not None:
            self._filling.join()
        self.server.stop()

    def go_to(self, name: str, clients: list | None = None) -> None:
        """Point the cameras of ``clients`` (default: every browser) along the training view ``name``."""
        view = next(v for v in self.views if v.name == name)
        rotation = view.cam_from_world[:3, :3]
        centre = -rotation.T @ view.cam_from_world[:3, 3]
        fov_y = 2 * np.arctan(view.camera.height / 2 / view.camera.fy)
        for client in self.server.get_clients().values() if clients is None else clients:
            with client.atomic():
                client.camera.position = centre
                client.camera.look_at = centre + rotation[2]  # the camera's +z axis in the world
                client.camera.up_direction = -rotation[1]  # OpenCV's y points down
                client.camera.fov = fov_y
        self.refresh()

    def refresh(self) -> None:
        """Render every browser's frame again (the model or the selection changed)."""
        for event in list(self._dirty.values()):
            event.set()

    def client_view(self, client) -> ViewCamera:
        """The pinhole view of a browser's current camera."""
        cam = client.camera
        return browser_camera(
            cam.wxyz,
            cam.position,
            cam.fov,
            cam.image_width,
            cam.image_height,
            max_size=self.max_size,
            near=self.session.scene.views[0].camera.near,
        )

    # --- browser tabs ---------------------------------------------------------------------

    def _connect(self, client) -> None:
        dirty = self._dirty[client.client_id] = threading.Event()
        client.camera.on_update(lambda _: dirty.set())
        threading.Thread(
            target=self._render_loop, args=(client, dirty), daemon=True, name=f"render-{client.client_id}"
        ).start()
        self.go_to(self._view.value, [client])

    def _render_loop(self, client, dirty: threading.Event) -> None:
        while True:
            dirty.wait()
            dirty.clear()
            if self._stopped.is_set() or client.client_id not in self._dirty:
                return
            with self._render_lock:
                frame = self.session.frame(self.client_view(client))
            if client.client_id in self._dirty:  # the tab may have closed meanwhile
                client.scene.set_background_image(frame, format="jpeg", jpeg_quality=92)

    def _click(self, event, mode: str) -> None:
        """A click selects (``select``), ctrl-click joins (``add``), shift-click splits
        (``exclude``): :meth:`ViewerSession.select_at`."""
        view = self.client_view(event.client)
        u, v = event.screen_pos[0] * view.camera.width, event.screen_pos[1] * view.camera.height
        try:
            with self._render_lock:
                selection = self.session.select_at(view, u, v, mode)
        except InputError as e:
            self._say(str(e))
            return
        clicks = len(self.session.clicks)
        held = (
            " The masks hold this object and its surroundings as one region and do not say where it ends: "
            "ctrl-click what the selection missed, shift-click what is not the object, and turn the model "
            "to click what this view does not show."
            if self.session.scene_held()
            else ""
        )
        self._say(
            f"Selected {int(selection.sum()):,} Gaussians by {clicks} click{'s' if clicks > 1 else ''} "
            f"(ctrl-click adds a part, shift-click takes one out).{held}"
        )
        self.refresh()

    # --- the scene and the panel ----------------------------------------------------------

    def _add_cameras(self) -> None:
        centres = np.stack([-v.cam_from_world[:3, :3].T @ v.cam_from_world[:3, 3] for v in self.views])
        scale = 0.05 * float(np.median(np.linalg.norm(centres - centres.mean(0), axis=1)) or 1.0)
        self._frustums = []
        for view, centre in zip(self.views, centres):
            wxyz = Rotation.from_matrix(view.cam_from_world[:3, :3].T).as_quat(scalar_first=True)
            self._frustums.append(
                self.server.scene.add_camera_frustum(
                    f"/cameras/{view.stem}",
                    fov=float(2 * np.arctan(view.camera.height / 2 / view.camera.fy)),
                    aspect=view.camera.width / view.camera.height,
                    scale=scale,
                    wxyz=wxyz,
                    position=centre,
                    color=(90, 90, 90),
                )
            )

    def _add_panel(self) -> None:
        gui, session = self.server.gui, self.session
        self._header = gui.add_markdown(self._header_text())
        self._status = gui.add_markdown(session.segments_missing or "Click an object to select it.")
        off = session.segmentation is None
        with gui.add_folder("Edit"):
            self._add_edit_controls(off)
        with gui.add_folder("Display"):
            self._add_display_controls(off)
        with gui.add_folder("Reassignment", expand_by_default=False):
            self._add_reassignment_controls(off)
        with gui.add_folder("Objects"):
            self._objects = gui.add_html(self._objects_table())

    def _add_edit_controls(self, off: bool) -> None:
        gui, session = self.server.gui, self.session
        buttons = {
            op: gui.add_button(label, disabled=off)
            for op, label in (("remove", "Remove"), ("extract", "Extract"), ("recolor", "Recolour"))
        }
        colour = gui.add_rgb("Colour", (230, 60, 60), disabled=off)
        undo = gui.add_button("Undo", disabled=off)
        name = gui.add_text("Edit name", "viewer", disabled=off)
        save = gui.add_button("Save", disabled=off)
        for op, button in buttons.items():
            button.on_click(lambda _, op=op: self._edit(op, tuple(colour.value) if op == "recolor" else None))

        @undo.on_click
        def _(_) -> None:
            step = session.undo()
            what = "" if step is None else ("the selection" if step.object_id is None else f"object {step.object_id}")
            self._say("Nothing to undo." if step is None else f"Took back: {step.op} of {what}.")
            self._changed()

        @save.on_click
        def _(_) -> None:
            try:
                out = session.save(name.value)
            except InputError as e:
                self._say(str(e))
                return
            self._say(f"Wrote `{out}`.")

    def _add_display_controls(self, off: bool) -> None:
        gui, session = self.server.gui, self.session
        self._view = gui.add_dropdown("View", tuple(v.name for v in self.views), initial_value=self.views[0].name)
        self._view.on_update(lambda _: self.go_to(self._view.value))
        cameras = gui.add_checkbox("Show cameras", True)
        segments = gui.add_checkbox("Show segments", False, disabled=off)

        @cameras.on_update
        def _(_) -> None:
            for frustum in self._frustums:
                frustum.visible = cameras.value

        @segments.on_update
        def _(_) -> None:
            session.show_segments = segments.value
            self.refresh()

    def _add_reassignment_controls(self, off: bool) -> None:
        gui, session = self.server.gui, self.session
        labels = session.segmentation
        method = gui.add_dropdown("Method", METHODS, initial_value=labels.method if labels else "prior", disabled=off)
        gamma = gui.add_slider("gamma_p", 0.0, 2.0, 0.05, labels.gamma_p if labels else 0.2, disabled=off)
        rerun = gui.add_button("Re-run reassignment", disabled=off)

        @rerun.on_click
        def _(_) -> None:
            try:
                seconds = session.relabel(method.value, gamma.value)
            except InputError as e:
                self._say(str(e))
                return
            self._say(f"Reassigned by {method.value}, gamma_p {gamma.value:g}, in {seconds:.2f} s.")
            self._changed()

    def _edit(self, op: str, color: tuple[int, int, int] | None) -> None:
        try:
            step = self.session.edit(op, color)
        except InputError as e:
            self._say(str(e))
            return
        done = {"remove": "Removed", "extract": "Extracted", "recolor": "Recoloured"}[op]
        what = "the selection" if step.object_id is None else f"object {step.object_id}"
        filling = op == "remove" and self.session.fill(wait=False) is None
        self._say(
            f"{done} {what}{'; filling what no photo saw' if filling else ''}; Undo takes it back, Save writes it."
        )
        self._changed()
        if filling:
            self._filling = threading.Thread(target=self._fill, args=(what,), name="fill")
            self._filling.start()

    def _fill(self, what: str) -> None:
        """Compute the removal's fill, then show it (unless the edits changed meanwhile)."""
        filled = self.session.fill()
        if filled is not None and self.session.fill(wait=False) is filled:
            self._say(
                f"Removed {what} and filled what no photo saw ({filled.added:,} Gaussians, {filled.seconds:.0f} s)."
            )
            self.refresh()

    def _header_text(self) -> str:
        """The run, the Gaussians shown now (after the edits) and the backend."""
        shown = len(self.session.current()[0])
        return (
            f"**{html.escape(str(self.session.run.root))}**: {shown:,} Gaussians, rendered by the "
            f"`{self.session.backend.name}` backend."
        )

    def _changed(self) -> None:
        self._header.content = self._header_text()
        self._objects.content = self._objects_table()
        self.refresh()

    def _say(self, text: str) -> None:
        self._status.content = text

    def _objects_table(self) -> str:
        rows = sorted(self.session.objects(), key=lambda row: -row[1])
        if not rows:
            return "<p>No objects.</p>"
        palette = label_palette()
        cells = "".join(
            f"<tr><td>{o}</td><td><span style='display:inline-block;width:1em;height:1em;"
            f"background:rgb{tuple(int(c) for c in palette[o])}'></span></td><td>{n:,}</td></tr>"
            for o, n in rows
        )
        return f"<table><tr><th>ID</th><th></th><th>Gaussians</th></tr>{cells}</table>"


def serve(
    run_dir: Path | str,
    *,
    scene_dir: Path | str | None = None,
    host: str = "127.0.0.1",
    port: int = 8080,
    max_size: int = 640,
    backend: str = "auto",
    other_scene: bool = False,
    fill: FillOptions = FillOptions(),
    on_ready=print,
) -> None:
    """Serve a run until Ctrl-C or SIGTERM (then :class:`Interrupted`, which the command line
    prints as one line with exit code 130, as every command); ``on_ready`` is called with a
    line saying where; ``other_scene``: show it on a scene other than the run's; ``fill``: the
    options of a removal's fill (:mod:`gsseg.fill`)."""
    # A frame queued for a tab that closed meanwhile is dropped; viser warns of it with a source line.
    warnings.filterwarnings("ignore", message=r"Queued a \w+ on a closed connection", category=UserWarning)
    session = ViewerSession(load_run(run_dir, other_scene=other_scene), scene_dir=scene_dir, backend=backend, fill=fill)
    viewer = Viewer(session, host=host, port=port, max_size=max_size)
    on_ready(f"serving {run_dir} at {viewer.url} (Ctrl-C stops)")
    if session.segments_missing:
        on_ready(session.segments_missing)
    try:
        with stop_requests() as stop:
            while not stop.requested:
                time.sleep(0.2)
    finally:
        viewer.stop()
    raise Interrupted(f"{stop.signal_name}: the viewer of {run_dir} stopped; the run is as it was.")
