"""The Jupyter viewer in a real browser: JupyterLab + headless Chromium, checked by pixel hashes.

One notebook shows ``Viewer(post.vtk, size=(480, 360))`` (then runs the cells of
``conftest.CELLS``); the tests run in order on that page
(starting JupyterLab and the kernel once keeps the whole module near half a minute):

* the viewer shows its full frame (480x360 pixels in the page's <img>);
* a frame asked for while another cell keeps the kernel busy arrives before that cell ends;
* the controls' echoes of their values draw nothing: two frames drawn in all before any input;
* a drag orbits and a wheel turn zooms: the picture's hash changes, then the full frame arrives;
* a click-and-drag on the histogram adds an opacity point: the picture changes, the full frame arrives;
* a 1 s drag of 30 moves is followed by the full frame within 2 s of mouse-up;
* in an 800 px wide window the picture keeps its aspect, is drawn at the size shown, and
  the viewer fits the window;
* the saved notebook holds a PNG of the first full frame beside the widget;
* no severe console errors.

A frame is "full" when the <img>'s natural size equals its size on the page (previews are
smaller and stretched) and the status line says so. Each frame's arrival is logged in the
page by a ``load`` listener on the <img> (``window.__frames``).
"""

from __future__ import annotations

import time

import pytest

from tests.browser.conftest import SIZE

pytestmark = [pytest.mark.gl, pytest.mark.data]

# FNV-1a over the RGBA bytes of what the <img> shows, with its natural size and its size on the
# page inside its 1 px border.
_HASH_JS = """
const img = document.querySelector(arguments[0] + ' img');
if (!img || !img.complete || img.naturalWidth < 2) return null;
const c = document.createElement('canvas');
c.width = img.naturalWidth; c.height = img.naturalHeight;
const g = c.getContext('2d', {willReadFrequently: true});
g.drawImage(img, 0, 0);
const d = g.getImageData(0, 0, c.width, c.height).data;
let h = 0x811c9dc5;
for (let i = 0; i < d.length; i++) { h ^= d[i]; h = Math.imul(h, 0x01000193) >>> 0; }
const r = img.getBoundingClientRect();
return {hash: h, nw: img.naturalWidth, nh: img.naturalHeight, w: img.clientWidth, h: img.clientHeight, right: r.right,
        status: (document.querySelector('.tetvr-status') || {}).textContent || ''};
"""

_WATCH_JS = """
const img = document.querySelector('.tetvr-image img');
if (!img || window.__watching) return !!img;
window.__watching = true; window.__frames = []; window.__statuses = []; window.__up = null;
img.addEventListener('load', () => window.__frames.push(
    {t: performance.now(), nw: img.naturalWidth, nh: img.naturalHeight}));
img.addEventListener('pointerup', () => { window.__up = performance.now(); }, true);
const st = document.querySelector('.tetvr-status');
new MutationObserver(() => window.__statuses.push(st.textContent)).observe(
    st, {subtree: true, childList: true, characterData: true});
return true;
"""


def _state(driver, which=".tetvr-image"):
    return driver.execute_script(_HASH_JS, which)


def _wait(driver, what, cond, timeout=30.0):
    end = time.monotonic() + timeout
    last = None
    while time.monotonic() < end:
        last = _state(driver)
        if last is not None and cond(last):
            return last
        time.sleep(0.05)
    pytest.fail(f"timed out after {timeout:.0f} s waiting for {what}; last state {last}")


def _is_full(s):
    # drawn at the size it is shown at (1 px of rounding), and the status line agrees
    return abs(s["nw"] - s["w"]) <= 1.5 and abs(s["nh"] - s["h"]) <= 1.5 and "full" in s["status"]


def _full_and_changed(before):
    return lambda s: _is_full(s) and s["hash"] != before["hash"]


# The input prompts ("[*]:" while a cell runs) and the text of each cell's output.
_CELLS_JS = """
return Array.from(document.querySelectorAll('.jp-Notebook .jp-Cell')).map(c => [
    (c.querySelector('.jp-InputPrompt') || {}).textContent || '',
    (c.querySelector('.jp-OutputArea') || {}).textContent || '']);
"""


def _cells(driver):
    return driver.execute_script(_CELLS_JS)


def _until(what, cond, timeout=60.0, every=0.05):
    end = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > end:
            pytest.fail(f"timed out after {timeout:.0f} s waiting for {what}")
        time.sleep(every)


@pytest.fixture(scope="module")
def page(lab, browser):
    """The notebook open and the viewer's cell run, its full frame shown; then the cells of
    ``conftest.CELLS``, one by one: what the page showed while the second kept the kernel
    busy, and the third's count of the frames drawn. Yields the driver, the first full
    frame's state and ``run``: ``busy_frame`` (the state of the frame that arrived while the
    kernel was busy, or None) and ``frames_drawn``."""
    from tests.browser.lab import open_and_run, run_cell

    open_and_run(browser, lab[0], ".tetvr-image img", all_cells=False)
    assert browser.execute_script(_WATCH_JS)
    first = _wait(browser, "the first full frame", _is_full, timeout=90)
    kernel = "window.jupyterapp.shell.currentWidget.sessionContext.session.kernel.status"
    _until("the kernel to take the page's messages", lambda: browser.execute_script(f"return {kernel}") == "idle")
    time.sleep(1.0)
    run = {"busy_frame": None, "frames_drawn": None}
    run_cell(browser, 1)
    _until("the second cell to print 'busy'", lambda: "busy" in _cells(browser)[1][1])
    before = _state(browser)
    while "*" in _cells(browser)[1][0]:  # while it runs: the frame it asked for 1 s into it
        s = _state(browser)
        if s is not None and _is_full(s) and s["hash"] != before["hash"]:
            run["busy_frame"] = s
            break
        time.sleep(0.05)
    _until("the second cell to end", lambda: "*" not in _cells(browser)[1][0], timeout=30)
    run_cell(browser, 2)
    _until("the third cell's count", lambda: "frames drawn" in _cells(browser)[2][1], timeout=90)
    run["frames_drawn"] = int(_cells(browser)[2][1].split("frames drawn:")[1].split()[0])
    # Back to the viewer: a picture scrolled out of view is sent no frames.
    browser.execute_script("window.jupyterapp.shell.currentWidget.content.activeCellIndex = 0;"
                           "document.querySelector('.tetvr-image img').scrollIntoView({block: 'start'});")
    return browser, first, run


def _drag(driver, selector, moves, dx, dy, seconds):
    from selenium.webdriver.common.action_chains import ActionChains

    el = driver.find_element("css selector", selector)
    chain = ActionChains(driver, duration=0).move_to_element(el).click_and_hold()
    for _ in range(moves):
        chain = chain.move_by_offset(dx, dy).pause(seconds / moves)
    chain.release().perform()


def test_the_viewer_shows_its_full_frame(page):
    _, first, _ = page
    assert (first["nw"], first["nh"]) == SIZE
    assert first["w"] / first["h"] == pytest.approx(4 / 3, rel=0.01)


def test_frames_arrive_while_a_cell_keeps_the_kernel_busy(page):
    # The render thread sends them: the kernel's event loop, which the cell blocks, is not involved.
    busy = page[2]["busy_frame"]
    assert busy is not None, "no new frame arrived while the second cell kept the kernel busy"
    assert (busy["nw"], busy["nh"]) == SIZE


def test_the_controls_echoing_their_values_draw_nothing(page):
    # The first full frame and the one the second cell asked for; the unit-distance slider's
    # echo of its value (1 ulp off through log10 and 10**x) used to add a preview and a full frame.
    assert page[2]["frames_drawn"] == 2


def test_a_drag_orbits_and_the_wheel_zooms(page):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.actions.wheel_input import ScrollOrigin

    driver = page[0]
    before = _state(driver)
    _drag(driver, ".tetvr-image img", 8, 12, 2, 0.3)
    orbited = _wait(driver, "the full frame after the drag", _full_and_changed(before))
    el = driver.find_element("css selector", ".tetvr-image img")
    ActionChains(driver).scroll_from_origin(ScrollOrigin.from_element(el), 0, -300).perform()
    zoomed = _wait(driver, "the full frame after the wheel", _full_and_changed(orbited))
    assert len({before["hash"], orbited["hash"], zoomed["hash"]}) == 3


def test_a_histogram_edit_changes_the_picture_and_the_full_frame_arrives(page):
    driver = page[0]
    before = _state(driver)
    hist_before = _state(driver, ".tetvr-hist")
    # Press on empty space at 40 % of the range, low opacity; drag the new point up.
    from selenium.webdriver.common.action_chains import ActionChains

    el = driver.find_element("css selector", ".tetvr-hist img")
    rect = el.rect
    x0, y0 = -rect["width"] * 0.1, rect["height"] * 0.2  # offsets from the element's centre
    ActionChains(driver, duration=0).move_to_element_with_offset(el, int(x0), int(y0)).click_and_hold() \
        .move_by_offset(0, -40).pause(0.1).move_by_offset(0, -20).release().perform()
    _wait(driver, "the full frame after the edit", _full_and_changed(before))
    assert _state(driver, ".tetvr-hist")["hash"] != hist_before["hash"]


def test_the_full_frame_follows_a_one_second_drag_within_two_seconds(page):
    driver = page[0]
    before = _state(driver)
    driver.execute_script("window.__frames = []; window.__statuses = []; window.__up = null;")
    _drag(driver, ".tetvr-image img", 30, -4, 1, 1.0)
    after = _wait(driver, "the full frame after a 1 s drag", _full_and_changed(before), timeout=20)
    frames, up, statuses = driver.execute_script("return [window.__frames, window.__up, window.__statuses]")
    assert up is not None, "the page saw no mouse-up"
    full = [f for f in frames if f["t"] > up and (f["nw"], f["nh"]) == (after["nw"], after["nh"])]
    assert full, f"no full frame logged after mouse-up: {frames}"
    delay = (full[0]["t"] - up) / 1000.0
    previews = [f for f in frames if f["t"] < up and f["nw"] < after["nw"]]
    assert previews, "no preview was shown during the drag"
    assert any("rendering" in s for s in statuses), f"no 'rendering…' feedback: {statuses[:10]}"
    print(f"full frame {delay:.2f} s after mouse-up; {len(previews)} previews during the drag")
    assert delay < 2.0, f"the full frame came {delay:.2f} s after mouse-up"


def test_the_layout_keeps_the_aspect_in_an_800px_window(page):
    driver = page[0]
    size = driver.get_window_size()
    try:
        before = _state(driver)
        driver.set_window_size(800, 900)
        state = _wait(driver, "a full frame after narrowing the window",
                      lambda s: _is_full(s) and s["right"] <= driver.execute_script("return window.innerWidth"))
        inner = driver.execute_script("return window.innerWidth")
        print(f"800 px window: picture {state}")
        assert state["w"] / state["h"] == pytest.approx(4 / 3, rel=0.02), state
        assert state["nw"] / state["nh"] == pytest.approx(4 / 3, rel=0.02), state
        assert state["w"] <= before["w"] + 1
        hist = driver.find_element("css selector", ".tetvr-hist img").rect
        assert hist["x"] + hist["width"] <= inner, "the histogram editor is off-screen"
        for button in driver.find_elements("css selector", ".tetvr-viewer button"):
            r = button.rect
            assert r["x"] + r["width"] <= inner, f"button {button.text!r} is off-screen"
    finally:
        driver.set_window_size(size["width"], size["height"])


def test_the_saved_notebook_keeps_a_picture(page, lab):
    import base64
    import json

    driver, first, _ = page
    path = lab[1]
    before = path.stat().st_mtime_ns
    driver.execute_script("window.jupyterapp.commands.execute('docmanager:save')")
    end = time.monotonic() + 20
    while path.stat().st_mtime_ns == before and time.monotonic() < end:
        time.sleep(0.1)
    # The server writes the file in place: a read just after the time changed can find it
    # empty or half written (seen on a loaded machine), so read until it parses.
    while True:
        try:
            notebook = json.loads(path.read_text())
            break
        except json.JSONDecodeError:
            if time.monotonic() > end:
                raise
            time.sleep(0.1)
    outputs = notebook["cells"][0]["outputs"]
    pngs = [o["data"]["image/png"] for o in outputs if "image/png" in o.get("data", {})]
    assert pngs, f"no image/png in the saved output: {[sorted(o.get('data', {})) for o in outputs]}"
    png = base64.b64decode(pngs[-1])
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and int.from_bytes(png[16:20], "big") == SIZE[0]
    assert any("application/vnd.jupyter.widget-view+json" in o.get("data", {}) for o in outputs)


def test_no_severe_console_errors(page):
    driver = page[0]
    severe = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"
              and "favicon" not in e["message"]]
    assert not severe, "\n".join(e["message"] for e in severe)
