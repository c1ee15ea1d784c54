"""A real headless Chromium for the report tests: Debian's ``chromium`` package driven by Playwright.

No browser is downloaded (never ``playwright install``): the test setup installs the distribution's package
with apt when it is missing and the tests run as root. Without it, the browser tests fail where the CI
environment variable is set and are skipped elsewhere, with the reason.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

CHROMIUM = Path("/usr/bin/chromium")
#: this machine has no network: background services would only flood the console with failed requests
FLAGS = (
    "--disable-gpu",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-quic",
)
INSTALL = (("apt-get", "update"), ("apt-get", "install", "-y", "chromium"))
INSTALL_TIMEOUT = 1200  # [s] a cold apt cache and a slow mirror


def is_root() -> bool:
    return hasattr(os, "geteuid") and os.geteuid() == 0


def ensure_chromium(
    executable: Path = CHROMIUM,
    *,
    root: bool | None = None,
    run: Callable[..., subprocess.CompletedProcess] = subprocess.run,
    which: Callable[[str], str | None] = shutil.which,
) -> str | None:
    """Make ``executable`` available: nothing to do when it is there; as root, ``apt-get update`` then
    ``apt-get install -y chromium`` (non-interactive). Return None when it is usable, else why not."""
    if executable.is_file() and os.access(executable, os.X_OK):
        return None
    if not (is_root() if root is None else root):
        return f"{executable} is missing and installing it needs root: sudo apt-get install chromium"
    if which("apt-get") is None:
        return f"{executable} is missing and there is no apt-get to install Debian's chromium package"
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    for command in INSTALL:
        try:
            done = run(list(command), env=env, capture_output=True, text=True, timeout=INSTALL_TIMEOUT, check=False)
        except (OSError, subprocess.TimeoutExpired) as exc:
            return f"`{' '.join(command)}` failed: {exc}"
        if done.returncode != 0:
            tail = (done.stderr or done.stdout or "").strip().splitlines()[-1:] or ["no output"]
            return f"`{' '.join(command)}` exited with {done.returncode}: {tail[0]}"
    if not executable.is_file():
        return f"apt-get installed chromium but {executable} is still missing"
    return None


def launch_args(*, root: bool | None = None) -> list[str]:
    """Chromium's flags: ``--no-sandbox`` only as root (its sandbox refuses to run as root)."""
    return [*(["--no-sandbox"] if (is_root() if root is None else root) else []), *FLAGS]


@dataclass
class PageLog:
    """What the page did while it loaded: console errors, uncaught errors, dialogs, requests for anything but
    the page itself."""

    console_errors: list[str] = field(default_factory=list)
    page_errors: list[str] = field(default_factory=list)
    dialogs: list[str] = field(default_factory=list)
    requests: list[str] = field(default_factory=list)


@contextmanager
def chromium_context(profile: Path) -> Iterator[Any]:
    """A persistent Chromium context on a fresh profile folder (``profile``), headless."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        context = playwright.chromium.launch_persistent_context(
            str(profile),
            executable_path=str(CHROMIUM),
            headless=True,
            args=launch_args(),
            viewport={"width": 1280, "height": 900},
            offline=True,
        )
        try:
            yield context
        finally:
            context.close()


def open_page(context: Any, html: Path) -> tuple[Any, PageLog]:
    """Load ``html`` through a file:// URL, recording what :class:`PageLog` lists; dialogs are dismissed."""
    page = context.new_page()
    log = PageLog()
    page.on("console", lambda message: log.console_errors.append(message.text) if message.type == "error" else None)
    page.on("pageerror", lambda error: log.page_errors.append(str(error)))

    def dialog(d: Any) -> None:
        log.dialogs.append(d.message)
        d.dismiss()

    page.on("dialog", dialog)
    url = html.resolve().as_uri()
    page.on("request", lambda request: log.requests.append(request.url) if request.url != url else None)
    page.goto(url, wait_until="load")
    return page, log


#: every <img> and <svg>: its box on the page and, for an image, whether it decoded
GRAPHICS_JS = """() => Array.from(document.querySelectorAll('img, svg')).map(e => {
    const box = e.getBoundingClientRect();
    return {tag: e.tagName.toLowerCase(), id: (e.closest('figure') || {}).id || '', width: box.width,
            height: box.height, decoded: e.tagName.toLowerCase() === 'img' ? e.complete && e.naturalWidth > 0 : true};
})"""


def screenshot_path(tmp_path: Path, name: str) -> Path:
    """Where a screenshot goes: ``$DDTRACK_SCREENSHOT_DIR`` when set (kept), else the test's tmp_path."""
    folder = Path(os.environ["DDTRACK_SCREENSHOT_DIR"]) if os.environ.get("DDTRACK_SCREENSHOT_DIR") else tmp_path
    folder.mkdir(parents=True, exist_ok=True)
    return folder / name
