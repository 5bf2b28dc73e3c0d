"""Start JupyterLab on 127.0.0.1 and Debian's headless Chromium: for tests/browser and bench/viewer.py.

Only loopback addresses; a random token and a free port; Selenium is given the system
chromedriver (so it never tries to download one) and Chromium a fresh profile with its
network services off. Each starter returns what it started and a ``stop`` that ends it
(the server's whole process group, kernels included).
"""

from __future__ import annotations

import importlib.util
import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path
from typing import Any, Callable

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--disable-dev-shm-usage")


def missing() -> str | None:
    """Why the browser cannot be driven here (None: it can)."""
    for path, how in ((CHROMIUM, "apt-get install chromium"), (CHROMEDRIVER, "apt-get install chromium-driver")):
        if not os.access(path, os.X_OK):
            return f"{path} is missing: {how} (as .ci/run does)"
    for module, package in (("selenium", "selenium"), ("jupyterlab", "jupyterlab"), ("jupyter_rfb", "jupyter_rfb")):
        if importlib.util.find_spec(module) is None:
            return f"{package} is not installed: pip install -e '.[widget,browser]'"
    return None


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def write_notebook(path: Path, *sources: str) -> None:
    """A notebook of code cells (Python 3 kernel)."""
    cells = [{"cell_type": "code", "execution_count": None, "id": f"cell{i}", "metadata": {}, "outputs": [],
              "source": src} for i, src in enumerate(sources)]
    path.write_text(json.dumps({"cells": cells, "metadata": {"kernelspec": {
        "display_name": "Python 3", "language": "python", "name": "python3"}}, "nbformat": 4, "nbformat_minor": 5}))


def start_lab(root: Path, timeout: float = 60.0) -> tuple[str, str, Callable[[], None]]:
    """JupyterLab serving ``root``: ``(base_url, token, stop)``. Raises RuntimeError with
    the end of its log if it does not answer."""
    port, token = free_port(), secrets.token_hex(16)
    env = dict(os.environ, JUPYTER_CONFIG_DIR=str(root / ".config"), JUPYTER_RUNTIME_DIR=str(root / ".runtime"),
               IPYTHONDIR=str(root / ".ipython"), JUPYTER_PLATFORM_DIRS="1", MPLBACKEND="Agg")
    log_path = root / "lab.log"
    log = open(log_path, "wb")
    cmd = [sys.executable, "-m", "jupyterlab", "--no-browser", "--ServerApp.ip=127.0.0.1", f"--ServerApp.port={port}",
           "--ServerApp.port_retries=0", f"--IdentityProvider.token={token}", f"--ServerApp.root_dir={root}",
           "--LabApp.expose_app_in_browser=True", "--LabApp.news_url=None", "--LabApp.check_for_updates_class="
           "jupyterlab.NeverCheckForUpdate", f"--LabApp.user_settings_dir={root / '.settings'}",
           f"--LabApp.workspaces_dir={root / '.workspaces'}", "--ServerApp.open_browser=False",
           "--LabApp.extension_manager=readonly", "--ServerApp.terminals_enabled=False"]
    if os.geteuid() == 0:  # CI containers run as root
        cmd.append("--ServerApp.allow_root=True")
    proc = subprocess.Popen(cmd, cwd=root, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)

    def stop() -> None:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGTERM)
            try:
                proc.wait(15)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(5)
        log.close()

    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + timeout
    try:
        while True:
            if proc.poll() is not None:
                raise RuntimeError(f"JupyterLab exited ({proc.returncode}):\n{log_path.read_text()[-3000:]}")
            try:
                with urllib.request.urlopen(f"{url}/api/status?token={token}", timeout=2) as r:
                    if r.status == 200:
                        return url, token, stop
            except OSError:
                pass
            if time.monotonic() > deadline:
                raise RuntimeError(f"JupyterLab did not answer in {timeout:.0f} s:\n{log_path.read_text()[-3000:]}")
            time.sleep(0.25)
    except BaseException:
        stop()
        raise


def start_browser(profile: Path, window: tuple[int, int] = (1280, 1000)) -> tuple[Any, Callable[[], None]]:
    """Headless Chromium through the system chromedriver: ``(driver, stop)``."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = str(CHROMIUM)
    for flag in (*CHROMIUM_FLAGS, f"--user-data-dir={profile}", f"--window-size={window[0]},{window[1]}"):
        opts.add_argument(flag)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    service = Service(str(CHROMEDRIVER), log_output=str(profile / "chromedriver.log"))
    driver = webdriver.Chrome(service=service, options=opts)

    def stop() -> None:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)

    return driver, stop


def run_cell(driver: Any, index: int) -> None:
    """Run the notebook's cell ``index`` (from 0)."""
    driver.execute_script(f"window.jupyterapp.shell.currentWidget.content.activeCellIndex = {int(index)};"
                          "window.jupyterapp.commands.execute('notebook:run-cell')")


def open_and_run(driver: Any, url: str, selector: str, timeout: float = 90.0, *, all_cells: bool = True) -> None:
    """Open a notebook, wait for its kernel, run all cells (or the first only), wait for
    ``selector`` to appear."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as ec
    from selenium.webdriver.support.ui import WebDriverWait

    driver.get(url)
    WebDriverWait(driver, timeout).until(ec.presence_of_element_located((By.CSS_SELECTOR, ".jp-Notebook .jp-Cell")))
    WebDriverWait(driver, timeout).until(lambda d: d.execute_script(
        "const w = window.jupyterapp && window.jupyterapp.shell.currentWidget;"
        "return !!(w && w.sessionContext && w.sessionContext.session && w.sessionContext.session.kernel"
        " && w.sessionContext.session.kernel.connectionStatus === 'connected')"))
    if all_cells:
        driver.execute_script("window.jupyterapp.commands.execute('notebook:run-all-cells')")
    else:
        run_cell(driver, 0)
    WebDriverWait(driver, timeout).until(ec.presence_of_element_located((By.CSS_SELECTOR, selector)))
