"""The playground in a real headless Chromium (selenium): the page draws, pushes, tunes and falls.

The browser is Debian's ``chromium`` with ``chromedriver`` (``.ci/run`` installs
them). A machine without them fails these tests: they are never skipped.
"""

from __future__ import annotations

import io
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

pytestmark = pytest.mark.slow

CHROMIUM = os.environ.get("EQUILIBRIST_CHROMIUM", shutil.which("chromium") or "/usr/bin/chromium")
CHROMEDRIVER = os.environ.get("EQUILIBRIST_CHROMEDRIVER",
                              shutil.which("chromedriver") or "/usr/bin/chromedriver")


@pytest.fixture(scope="module")
def server():
    """``equilibrist play`` on a free loopback port, as a user starts it."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "equilibrist.cli.main", "play", "--no-browser", "--port", "0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env=dict(os.environ, PYTHONUNBUFFERED="1"))
    line = proc.stdout.readline()
    assert line.startswith("equilibrist playground at "), line + proc.stderr.read()
    yield line.split()[3]
    proc.send_signal(signal.SIGINT)
    proc.communicate(timeout=20)


def chromium(*extra):
    for path, what in ((CHROMIUM, "chromium"), (CHROMEDRIVER, "chromedriver")):
        if not os.path.exists(path):
            pytest.fail(f"{what} is missing ({path}): install Debian's chromium and "
                        "chromium-driver (.ci/run does)")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1400,1400", *extra):
        opts.add_argument(arg)
    return webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)


@pytest.fixture(scope="module")
def browser():
    driver = chromium()
    yield driver
    driver.quit()


def open_socket(driver, url):
    """What a script of the page open in *driver* gets from a socket to *url*: ``"refused"``
    when it closes before it opens, else the first message's type."""
    driver.set_script_timeout(60)
    return driver.execute_async_script("""
        const done = arguments[arguments.length - 1];
        const ws = new WebSocket(arguments[0]);
        let opened = false;
        ws.onopen = () => { opened = true; };
        ws.onmessage = (e) => { done(JSON.parse(e.data).type); ws.close(); };
        ws.onclose = () => { if (!opened) done("refused"); };
        """, url)


def test_a_page_from_a_foreign_name_is_refused(server):
    """DNS rebinding: another site's name made to resolve to this machine (here by the
    browser's own resolver rules) gets no page, and its page's socket gets no session."""
    port = server.rstrip("/").rsplit(":", 1)[1]
    driver = chromium("--host-resolver-rules=MAP attacker.example 127.0.0.1")
    try:
        driver.get(f"http://attacker.example:{port}/")
        text = driver.execute_script("return document.body ? document.body.innerText : ''")
        assert "not this playground's address" in text, text
        assert driver.execute_script("return typeof window.playground") == "undefined"
        # That page's script, to the same server under its own name and under the real one.
        assert open_socket(driver, f"ws://attacker.example:{port}/ws") == "refused"
        assert open_socket(driver, f"ws://127.0.0.1:{port}/ws") == "refused"
        # The same browser, at the playground's own address: the page and a session.
        driver.get(server)
        wait_for(lambda: driver.execute_script(
            "return window.playground && window.playground.frames > 0"), 60, "the page's frames")
        assert open_socket(driver, f"ws://127.0.0.1:{port}/ws") == "hello"
    finally:
        driver.quit()


def wait_for(predicate, timeout=15.0, what="the condition"):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def frame(driver):
    return driver.execute_script("return window.playground.frame")


def button(driver, text):
    from selenium.webdriver.common.by import By

    return driver.find_element(By.XPATH, f"//button[normalize-space()='{text}']")


def canvas_pixels(driver):
    from PIL import Image
    from selenium.webdriver.common.by import By

    png = driver.find_element(By.ID, "scene").screenshot_as_png
    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=int)
    return img[50:]  # below the time stamp and the push note drawn at the top right


@pytest.fixture(scope="module")
def page(server, browser):
    browser.get(server)
    wait_for(lambda: browser.execute_script(
        "return window.playground.frames > 10 && window.playground.design !== null"),
        30, "the first frames")
    return browser


def test_page_draws_and_moves(page):
    from selenium.webdriver.common.by import By

    # Kick the pole: it swings back up, and the drawing must follow. (The page may lag
    # behind the server on a busy machine: wait for the frames, not for the clock.)
    states = page.execute_script("return window.playground.sys.states")
    i = states.index("theta")
    button(page, "Kick").click()
    kicked = wait_for(lambda: abs((f := frame(page))["x"][i]) > 0.04 and f, 60, "the kick")
    first = canvas_pixels(page)
    assert (first != 255).any(axis=2).mean() > 0.02  # something is drawn
    wait_for(lambda: abs(frame(page)["x"][i] - kicked["x"][i]) > 0.02, 60, "the swing")
    second = canvas_pixels(page)
    assert (first != second).any(axis=2).sum() > 20  # and it moved (the time stamp excluded)
    frames0 = page.execute_script("return window.playground.frames")
    wait_for(lambda: page.execute_script("return window.playground.frames") - frames0 >= 25,
             60, "more frames")
    # Every control has a visible label or an accessible name.
    unnamed = page.execute_script("""
        const bad = [];
        for (const el of document.querySelectorAll('button, input, select')) {
          const named = (el.textContent || '').trim() || el.getAttribute('aria-label') ||
            (el.id && document.querySelector(`label[for="${el.id}"]`)) || el.closest('label');
          if (!named) bad.push(el.outerHTML.slice(0, 80));
        }
        return bad;""")
    assert unnamed == []
    assert page.find_element(By.ID, "chart-area").find_elements(By.CSS_SELECTOR, ".uplot")


def test_push_right_moves_the_cart_right(page):
    states = page.execute_script("return window.playground.sys.states")
    i = states.index("x_dot")
    pushes = frame(page)["pushes"]
    button(page, "Push right").click()
    wait_for(lambda: (f := frame(page))["pushes"] > pushes and f["push"] == 0, 60, "the push")
    history = page.execute_script("return window.playground.history")
    # The frames just before the push and just after it.
    start = next(k for k, h in enumerate(history) if h["pushes"] > pushes)
    end = next(k for k in range(start, len(history)) if history[k]["push"] == 0)
    gained = history[end]["x"][i] - history[start - 1]["x"][i]
    assert gained > 0.3  # 100 N for 0.1 s on 11 kg: about 0.9 m/s


def test_weight_slider_changes_gains_and_poles(page):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    gains0 = page.find_element(By.ID, "gains").text
    poles0 = page.find_element(By.ID, "poles").get_attribute("data-poles")
    slider = page.find_element(By.ID, "scale-theta")
    slider.send_keys(*([Keys.ARROW_LEFT] * 60))
    wait_for(lambda: page.find_element(By.ID, "gains").text != gains0, 60, "new gains")
    wait_for(lambda: page.find_element(By.ID, "poles").get_attribute("data-poles") != poles0,
             60, "new poles")
    poles = json.loads(page.find_element(By.ID, "poles").get_attribute("data-poles"))
    assert all(abs(complex(p["re"], p["im"])) < 1 for p in poles)
    assert frame(page)["fell"] is None


def test_controller_off_falls(page):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    Select(page.find_element(By.ID, "controller")).select_by_visible_text("Off")
    button(page, "Kick").click()
    try:
        wait_for(lambda: "Fell" in page.find_element(By.ID, "status").text, 60, "the fall")
    except AssertionError:
        raise AssertionError(page.execute_script(
            "const p = window.playground; return [document.getElementById('status').textContent,"
            " document.getElementById('message').textContent, p.tuneInFlight, p.tunePending,"
            " p.frame.controller, p.ws.readyState]")) from None
    assert frame(page)["fell"]["state"] == "theta"
    Select(page.find_element(By.ID, "controller")).select_by_value("lqg")
    wait_for(lambda: page.execute_script(
        "const d = window.playground.design; return d && d.controller === 'lqg'"), 60, "LQG back")
    button(page, "Reset").click()
    wait_for(lambda: "Running" in page.find_element(By.ID, "status").text, 60, "the restart")


def wrapped(angle):
    return (angle + math.pi) % (2 * math.pi) - math.pi


def test_swingup_from_hanging(page):
    """Swing-up picked, Hang pressed: the pole starts hanging, pumps, comes up and balances."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    states = page.execute_script("return window.playground.sys.states")
    i_th, i_x = states.index("theta"), states.index("x")
    Select(page.find_element(By.ID, "controller")).select_by_value("swingup")
    wait_for(lambda: page.execute_script(
        "const d = window.playground.design; return d && d.controller === 'swingup'"), 30,
        "the swing-up's design")
    run = frame(page)["run"]
    button(page, "Hang").click()
    wait_for(lambda: (f := frame(page))["run"] > run and f["hanging"], 30, "the hanging run")
    # (The frames from here on are the hanging run's; the charts start again with its start.)
    t0, theta0 = page.execute_script(
        f"const d = window.playground.data; return [d.t[0], d.x[{i_th}][0]]")
    assert t0 == 0 and abs(abs(theta0) - math.pi) < 0.06
    up = wait_for(lambda: (f := frame(page))["mode"] == "balancing"
                  and abs(wrapped(f["x"][i_th])) < 0.1 and f, 40, "the pole up and balanced")
    assert up["fell"] is None and 0.5 < up["t"] < 10.0
    assert "mode: balancing" in page.find_element(By.ID, "mode").text
    history = page.execute_script("return window.playground.history")
    hanging_run = [h for h in history if h["run"] == up["run"] and h["t"] <= up["t"]]
    assert any(h["mode"] == "pumping" for h in hanging_run)  # it pumped before it caught
    assert max(abs(h["x"][i_x]) for h in hanging_run) < 1.0  # on its track


def test_mpc_rejects_a_push_within_its_limits(page):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    states = page.execute_script("return window.playground.sys.states")
    i_th = states.index("theta")
    Select(page.find_element(By.ID, "controller")).select_by_value("mpc")
    wait_for(lambda: page.execute_script(
        "const d = window.playground.design; return d && d.controller === 'mpc'"), 30,
        "the MPC's design")
    run = frame(page)["run"]
    button(page, "Reset").click()
    wait_for(lambda: (f := frame(page))["run"] > run and f["solve"] is not None, 30, "the MPC running")
    assert "MPC solve per sample: median" in page.find_element(By.ID, "solve").text
    pushes = frame(page)["pushes"]
    button(page, "Push right").click()
    wait_for(lambda: (f := frame(page))["pushes"] > pushes and f["push"] == 0, 30, "the push")
    t_push = frame(page)["t"]
    settled = wait_for(lambda: (f := frame(page))["t"] > t_push + 2.0 and f, 30, "2 s after the push")
    assert settled["fell"] is None and abs(settled["x"][i_th]) < 0.1
    lo, hi = page.execute_script("return window.playground.sys.input_limits[0]")
    history = page.execute_script("return window.playground.history")
    after = [h for h in history if h["run"] == settled["run"] and h["t"] >= t_push - 0.2]
    assert after and all(lo - 1e-9 <= h["u_cmd"][0] <= hi + 1e-9 for h in after)


def test_picker_disables_swingup_where_there_is_none(page):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    Select(page.find_element(By.ID, "system")).select_by_value("seesaw")
    wait_for(lambda: page.execute_script(
        "const s = window.playground.sys; return s && s.name === 'seesaw'"), 60, "the seesaw")
    option = page.find_element(By.CSS_SELECTOR, "#controller option[value='swingup']")
    assert not option.is_enabled()
    assert "no hanging position" in option.get_attribute("title")
    assert page.find_element(By.CSS_SELECTOR, "#controller option[value='mpc']").is_enabled()
    assert not page.find_element(By.ID, "hang").is_enabled()


#: A server whose registry also holds the swing-up's record under another name and label
#: (a kind of one's own could be exactly this), started as a user's script would.
RENAMED_SERVER = """
import dataclasses, sys
from equilibrist.controllers import kinds
kinds.register(dataclasses.replace(kinds.get("swingup"), name="twinswingup",
                                   label="Twin swing-up (a copy)", order=100))
from equilibrist.cli.main import main
sys.exit(main(["play", "--no-browser", "--port", "0"]))
"""


@pytest.fixture(scope="module")
def renamed_server():
    proc = subprocess.Popen([sys.executable, "-c", RENAMED_SERVER],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, PYTHONUNBUFFERED="1"))
    line = proc.stdout.readline()
    assert line.startswith("equilibrist playground at "), line + proc.stderr.read()
    yield line.split()[3]
    proc.send_signal(signal.SIGINT)
    proc.communicate(timeout=20)


def test_a_renamed_swingup_shows_as_the_swingup(renamed_server):
    """The page reads what it shows of a controller from its kind's record, not its name:
    the swing-up's record under another name is offered as a way up in the Hang button's hint,
    needs no hint itself, and shows the swing-up's design line, status and caught note."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    driver = chromium()
    try:
        driver.get(renamed_server)
        wait_for(lambda: driver.execute_script(
            "return window.playground.frames > 10 && window.playground.design !== null"),
            30, "the first frames")
        message = lambda: driver.find_element(By.ID, "message").text  # noqa: E731
        # Hanging with the LQG: the hint names every kind that brings the pole up.
        run = frame(driver)["run"]
        button(driver, "Hang").click()
        wait_for(lambda: "Hanging:" in message(), 30, "the Hang hint")
        assert message() == ("Hanging: pick Swing-up, Time-varying LQR or Twin swing-up in the "
                             "Controller menu to bring it up.")
        wait_for(lambda: frame(driver)["run"] > run, 30, "the hanging run")
        Select(driver.find_element(By.ID, "controller")).select_by_value("twinswingup")
        wait_for(lambda: driver.execute_script(
            "const d = window.playground.design; return d && d.controller === 'twinswingup'"),
            30, "the renamed swing-up's design")
        info = driver.find_element(By.ID, "design-info").text
        assert info.startswith("Twin swing-up (") and "handing over to the LQR below" in info, info
        driver.execute_script("document.getElementById('message').textContent = ''")
        run = frame(driver)["run"]
        button(driver, "Hang").click()
        wait_for(lambda: (f := frame(driver))["run"] > run and f["hanging"], 30,
                 "the hanging run")
        assert "Hanging:" not in message()  # it brings the pole up itself: no hint
        wait_for(lambda: "Running (twin swing-up, started hanging)"
                 in driver.find_element(By.ID, "status").text, 30, "the status")
        wait_for(lambda: "(caught: the LQR balances)" in driver.find_element(By.ID, "mode").text,
                 60, "the swing-up's caught note")
        assert "mode: balancing" in driver.find_element(By.ID, "mode").text
    finally:
        driver.quit()
