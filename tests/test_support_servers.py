"""The real servers the tests use start and answer: PostgreSQL (tests/pg_server.py) and Chromium (tests/browser.py)."""

import http.server
import subprocess
import threading

from tests.pg_server import postgres_bin_dir


def test_postgres_fixture_serves_a_database_on_loopback(postgres):
    psql = str(postgres_bin_dir() / "psql")
    out = subprocess.run(
        [psql, postgres.url, "-tAc", "SELECT current_user, inet_server_addr()"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "harp|127.0.0.1"
    other = postgres.create_database("support_check")
    out = subprocess.run([psql, other, "-tAc", "SELECT current_database()"], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "support_check"


def test_browser_fixture_renders_a_local_page(page, tmp_path):
    (tmp_path / "index.html").write_text(
        "<title>harp</title><p id=x>strings</p><script>document.getElementById"
        "('x').textContent += ' seen by js'</script>"
    )

    class Handler(http.server.SimpleHTTPRequestHandler):
        def __init__(self, *a, **k):
            super().__init__(*a, directory=str(tmp_path), **k)

        def log_message(self, *a):  # quiet
            pass

    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    try:
        page.goto(f"http://127.0.0.1:{srv.server_port}/index.html")
        assert page.title() == "harp"
        assert page.text_content("#x") == "strings seen by js"
    finally:
        srv.shutdown()
        srv.server_close()
