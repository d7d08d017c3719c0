"""The runs compare page gives a judged best's judged distance, speed and COT (the figures it ranks by)."""

from __future__ import annotations


def test_the_compare_page_shows_the_judged_bests_figures(browser, judged_server):
    page = browser.new_page()
    page.goto(f"{judged_server.url}/#/compare/run-c,run-v8")
    page.wait_for_selector("#compare-table tbody tr >> nth=1")
    row = page.locator('#compare-table tr[data-run="run-c"]')
    shown = {k: row.locator(f'td[data-best="{k}"]').inner_text() for k in ("distance_m", "speed_cm_s", "cot")}
    page.close()
    # run-c's best, trial 1: screened 0.30 m, COT 2.2 (6 cm/s over 5 s); judged 0.40 m, COT 5.5: 8 cm/s
    assert shown == {"distance_m": "0.4", "speed_cm_s": "8", "cot": "5.5"}
