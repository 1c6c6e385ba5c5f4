"""The playground's region of attraction in a real headless Chromium: the button draws the
slice, the live state moves on it, a certified level is outlined, a change of controller
clears it. (The server and the browser as in ``test_web_browser.py``; never skipped.)"""

from __future__ import annotations

import json

import pytest
import test_web_browser as _shared  # beside this file (tests/web/)
from test_web_browser import button, wait_for

pytestmark = pytest.mark.slow

# The playground served as a user starts it, a headless Chromium, the page open in it.
server = _shared.server
browser = _shared.browser
page = _shared.page


def roa_canvas(driver):
    from selenium.webdriver.common.by import By

    return driver.find_element(By.ID, "roa")


def test_the_region_of_attraction_is_drawn_and_the_live_state_moves_on_it(page):
    from selenium.webdriver.common.by import By

    cv = roa_canvas(page)
    assert not cv.is_displayed()
    button(page, "Region of attraction").click()
    wait_for(lambda: int(cv.get_attribute("data-points") or 0) > 0, 60, "the slice drawn")
    assert cv.is_displayed()
    status = page.find_element(By.ID, "roa-status").text
    assert "theta, theta_dot" in status and "caught" in status, status
    s = page.execute_script("return window.playground.roa.slice")
    assert s["states"] == ["theta", "theta_dot"] and set(s["caught"]) == {"0", "1"}
    # Both outcomes shaded: the light teal of caught, the light red of not caught.
    colours = page.execute_script("""
        const cv = document.getElementById('roa'), ctx = cv.getContext('2d');
        const d = ctx.getImageData(0, 0, cv.width, cv.height).data, seen = new Set();
        for (let k = 0; k < d.length; k += 4 * 7) seen.add(`${d[k]},${d[k + 1]},${d[k + 2]}`);
        return [...seen];""")
    assert "207,233,228" in colours and "247,217,207" in colours
    # The live dot is drawn where the frame's state is, and follows it frame by frame.
    def dot_and_state():
        return page.execute_script(
            "const p = window.playground, cv = document.getElementById('roa');"
            "return [cv.dataset.dot ? JSON.parse(cv.dataset.dot) : null, p.frame.x, "
            "+cv.dataset.drawn];")

    dot, x, drawn = wait_for(lambda: (v := dot_and_state())[0] and v, 30, "the live dot")
    (x0, x1), (y0, y1) = s["bounds"]
    i, j = s["index"]
    w, h = 640 - 62 - 14, 380 - 12 - 40
    px = 62 + (min(max(x[i], x0), x1) - x0) / (x1 - x0) * w
    py = 12 + (y1 - min(max(x[j], y0), y1)) / (y1 - y0) * h
    assert abs(dot[0] - px) < 0.02 and abs(dot[1] - py) < 0.02, (dot, px, py)
    button(page, "Kick").click()
    seen = {json.dumps(dot)}
    wait_for(lambda: seen.add(json.dumps(dot_and_state()[0])) or len(seen) >= 5, 30,
             "the live dot moving")
    assert dot_and_state()[2] > drawn + 4  # redrawn at the frames


def test_a_certified_level_is_outlined_and_a_new_controller_clears_the_view(page):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    cv = roa_canvas(page)
    wait_for(lambda: int(cv.get_attribute("data-points") or 0) > 0, 60, "the slice drawn")
    # A certificate frame as the server sends it (the real one takes seconds): the unit
    # circle's section through (0.5 rad, 0), outlined in black. (One script: no frame of
    # the server comes in between.)
    s = page.execute_script("return window.playground.roa.slice")
    (x0, x1), (y0, y1) = s["bounds"]
    px = round(62 + (0.5 - x0) / (x1 - x0) * 564)
    py = round(12 + (y1 - 0.0) / (y1 - y0) * 328)
    rho, dark = page.execute_script(f"""
        const p = window.playground, cv = document.getElementById('roa');
        p.hooks.roa({{type: 'roa', status: 'certificate', id: p.roa.slice.id, note: null,
          certificate: {{rho: 0.25, S: [[1, 0], [0, 1]], center: [0, 0], certified: true,
            limited_by: 'region', boxes: 1, seconds: 0.1, assumes: 'a test',
            method: 'a test', counterexamples: 0}}}});
        const d = cv.getContext('2d').getImageData({px} - 2, {py} - 2, 5, 5).data;
        let dark = 0;
        for (let k = 0; k < d.length; k += 4) if (d[k] < 80 && d[k + 1] < 80 && d[k + 2] < 80) dark++;
        return [cv.dataset.rho, dark];""")
    assert rho == "0.25" and dark > 0
    assert "Proven" in page.find_element(By.ID, "roa-status").text
    # Another controller: the slice shown was the previous loop's.
    Select(page.find_element(By.ID, "controller")).select_by_value("lqr")
    wait_for(lambda: cv.get_attribute("data-points") == "0", 60, "the view cleared")
    assert "changed" in page.find_element(By.ID, "roa-status").text
