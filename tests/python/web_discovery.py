"""The Diagnosis tab's discovery in headless Chromium: found outside the library, then
accepted into the campaign and fitted by its next run (run through web_ui.py):

    python3 web_ui.py discovery URL RECORD.csv SCREENSHOT.png OUT.json

RECORD.csv is the driven Furuta rig with a cogging torque on the arm
(furuta_extra_torque.py). On the page: the record uploaded, the two angles mapped, the
motor torque driving armTorque, the two frictions calibrated (Nelder-Mead and
Levenberg-Marquardt, two starts); the Diagnosis tab run with "Also look outside the effect
library"; the proposal read off the page (formula in symbols and words, the terms with
their intervals, the harmonic, the refit's objectives) and pictured (SCREENSHOT.png); "Add
to the campaign" pressed, the Calibration tab's form read (the effect listed), the campaign
started and its result read (free parameters, best objective), with what the server keeps
of both campaigns. Writes what it read as JSON to OUT.json; exits non-zero when a step fails.
"""

import json
import os

from selenium.webdriver.common.by import By
from selenium.webdriver.support import expected_conditions as EC
from selenium.webdriver.support.ui import Select

from web_ui import LONG, browser, by_id, get_campaign, no_error, press, tab, type_into, upload, wait


def set_up_campaign(driver, url, record):
    driver.get(url)
    wait(driver).until(lambda d: d.find_elements(By.ID, "value-theta0"))
    Select(by_id(driver, "model-select")).select_by_value("furuta")
    wait(driver).until(lambda d: d.find_elements(By.ID, "value-theta0"))
    upload(driver, record, "time_s")
    wait(driver).until(lambda d: "samples" in by_id(d, "measurement-status").text
                       or by_id(d, "measurement-error").is_displayed())
    no_error(driver, "measurement-error")
    tab(driver, "calibration")
    Select(by_id(driver, "measured-armJoint.phi")).select_by_value("arm_angle_rad")
    Select(by_id(driver, "measured-pendulumJoint.phi")).select_by_value("pendulum_angle_rad")
    Select(by_id(driver, "input-armTorque")).select_by_value("motor_torque_Nm")
    for name, nominal in (("armFriction", "0.012"), ("pendulumFriction", "0.002")):
        press(driver, f"free-{name}")
        type_into(driver, f"nominal-{name}", nominal)
        type_into(driver, f"min-{name}", "1e-4")
        type_into(driver, f"max-{name}", "0.9")
        Select(by_id(driver, f"pscale-{name}")).select_by_value("log10")
    driver.find_element(By.CSS_SELECTOR, 'input[name="method"][value="levenberg-marquardt"]').click()
    type_into(driver, "campaign-name", "cogging")
    type_into(driver, "window-start", "0")
    type_into(driver, "window-stop", "20")
    type_into(driver, "starts", "2")
    type_into(driver, "max-evaluations", "400")
    type_into(driver, "seed", "1")


def run_campaign(driver):
    """Start the form's campaign; its id and its state once finished."""
    driver.execute_script("document.getElementById('result').hidden = true")
    press(driver, "start")
    wait(driver, LONG).until(lambda d: by_id(d, "result").is_displayed()
                             or by_id(d, "calibration-error").is_displayed())
    no_error(driver, "calibration-error")
    hash_ = driver.execute_script("return location.hash")
    id_ = hash_.split("/campaign/")[1].split("/")[0]
    return id_, json.loads(get_campaign(driver, id_))


def read_proposal(driver):
    card = driver.find_element(By.CSS_SELECTOR, "#discovery-proposals article.proposal")
    terms = [{
        "parameter": row.get_attribute("data-parameter"),
        "function": row.find_element(By.CSS_SELECTOR, "td code").text,
        "estimate": row.find_element(By.CSS_SELECTOR, "td.estimate").get_attribute("data-value"),
        "low": row.find_element(By.CSS_SELECTOR, "td.interval").get_attribute("data-low"),
        "high": row.find_element(By.CSS_SELECTOR, "td.interval").get_attribute("data-high"),
        "text": row.text,
    } for row in card.find_elements(By.CSS_SELECTOR, "table.terms tbody tr")]
    harmonics = [{
        "multiple": h.get_attribute("data-multiple"),
        "amplitude": h.get_attribute("data-amplitude"),
        "low": h.get_attribute("data-low"),
        "high": h.get_attribute("data-high"),
        "text": h.text,
    } for h in card.find_elements(By.CSS_SELECTOR, "li.harmonic")]
    refit = card.find_element(By.CSS_SELECTOR, "p.refit")
    return {
        "heading": card.find_element(By.CSS_SELECTOR, "h4").text,
        "formula": card.find_element(By.CSS_SELECTOR, "code.formula").text,
        "words": card.find_element(By.CSS_SELECTOR, "p.formula-words").text,
        "terms": terms,
        "harmonics": harmonics,
        "refit": {k: refit.get_attribute(f"data-{k}") for k in ("before", "after", "ratio-before", "ratio-after")},
        "refit_text": refit.text,
        "toml": card.find_element(By.CSS_SELECTOR, "pre.toml").text,
        "summary": by_id(driver, "discovery-summary").text,
    }


def discovery(url, record, shot, out):
    driver = browser()
    driver.set_script_timeout(60)
    try:
        set_up_campaign(driver, url, record)
        first_id, first = run_campaign(driver)

        # Diagnosis, and what it found outside the library.
        tab(driver, "diagnosis")
        wait(driver).until(lambda d: any(o.get_attribute("value") == first_id
                                         for o in Select(by_id(d, "diagnosis-campaign")).options))
        Select(by_id(driver, "diagnosis-campaign")).select_by_value(first_id)
        by_id(driver, "diagnosis-discover").click()
        press(driver, "diagnose")
        wait(driver, LONG).until(lambda d: by_id(d, "discovery").is_displayed()
                                 or by_id(d, "diagnosis-error").is_displayed())
        no_error(driver, "diagnosis-error")
        proposal = read_proposal(driver)
        # The section alone, the sticky header out of its way.
        section = by_id(driver, "discovery")
        driver.set_window_size(1366, 4000)
        driver.execute_script("document.querySelector('header').style.position = 'static';"
                              "arguments[0].scrollIntoView({block: 'start'})", section)
        section.screenshot(shot)
        driver.execute_script("document.querySelector('header').style.position = ''")
        driver.set_window_size(1366, 900)

        # Accepted into the campaign: the form holds it; the next run fits it.
        press(driver, "proposal-0-accept")
        wait(driver).until(EC.visibility_of_element_located((By.ID, "defined-effects")))
        form = {
            "effects": [e.get_attribute("data-effect") for e in
                        driver.find_elements(By.CSS_SELECTOR, "#defined-effect-list .defined-effect")],
            "formula": driver.find_element(By.CSS_SELECTOR, "#defined-effect-list code.formula").text,
            "parameters": [r.get_attribute("data-parameter") for r in
                           driver.find_elements(By.CSS_SELECTOR, "#defined-effect-list tbody tr")],
            "status": by_id(driver, "calibration-status").text,
        }
        second_id, second = run_campaign(driver)
        result_rows = {row.get_attribute("data-parameter"):
                       row.find_element(By.CSS_SELECTOR, "td.calibrated").get_attribute("data-value")
                       for row in driver.find_elements(By.CSS_SELECTOR, "#result-parameters tbody tr")}
        with open(out, "w") as f:
            json.dump({
                "first": {"id": first_id, "objective": first["result"]["best"]["objective"]},
                "proposal": proposal,
                "form": form,
                "second": {
                    "id": second_id,
                    "objective": second["result"]["best"]["objective"],
                    "free": [p["name"] for p in second["result"]["free_parameters"]],
                    "defined_effects": second["campaign"].get("defined_effects", []),
                    "parameters": second["result"]["best"]["parameters"],
                },
                "result_rows": result_rows,
            }, f, indent=2)
    finally:
        driver.quit()


if __name__ == "__main__":
    raise SystemExit("run through web_ui.py: python3 web_ui.py discovery URL RECORD.csv SHOT.png OUT.json")
