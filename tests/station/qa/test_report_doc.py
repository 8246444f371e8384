"""The report's one document written twice (station/qa/report_doc.py): Markdown and the HTML page."""

from station.qa.report import write_report


def test_markdown_and_page_say_the_same_blocks(tmp_path):
    warning = "the camera reported itself as <X> & co, check it"
    md_path = write_report(
        tmp_path,
        "lens A",
        [],
        "FAIL",
        context=[("session", "`/s/1`"), ("camera", "m (**does not match**)")],
        warnings=[warning],
        notes=["a note"],
    )
    md = md_path.read_text()
    page = (tmp_path / "index.html").read_text()
    assert md.startswith("# QA report: lens A\n\n**Verdict: FAIL**\n\n")
    assert "| | |\n|:---|:---|\n| report written | " in md
    assert "| session | `/s/1` |\n| camera | m (**does not match**) |\n\n" in md
    assert f"| camera | m (**does not match**) |\n\n> **warning**: {warning}\n\n| focus | verdict |" in md
    assert md.endswith("|---:|:---:|---:|---:|---:|---:|:---|\n\n> a note\n\n")  # no focus rows
    assert "<title>QA report: lens A</title>" in page
    assert '<p><strong class="verdict fail">Verdict: FAIL</strong></p>' in page
    assert '<td style="text-align:left"><code>/s/1</code></td>' in page
    assert '<td style="text-align:left">m (<strong>does not match</strong>)</td>' in page
    assert (
        "<blockquote><strong>warning</strong>: the camera reported itself as &lt;X&gt; &amp; co, check it</blockquote>"
        in page
    )
    assert "<blockquote>a note</blockquote>" in page


def test_a_verdict_other_than_pass_or_fail_is_not_coloured(tmp_path):
    write_report(tmp_path, "x", [], "INCOMPLETE")
    page = (tmp_path / "index.html").read_text()
    assert "<p><strong>Verdict: INCOMPLETE</strong></p>" in page and 'class="verdict' not in page
