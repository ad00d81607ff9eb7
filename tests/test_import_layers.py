"""The package's import layers and loops, as the import-linter contracts in pyproject.toml state them."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LINT = "import sys; from importlinter.cli import lint_imports_command; sys.exit(lint_imports_command())"


def test_import_contracts_are_kept():
    """``lint-imports`` (the test extra installs import-linter) keeps every contract."""
    run = subprocess.run([sys.executable, "-c", LINT, "--no-cache"], check=False, cwd=ROOT, capture_output=True,
                         text=True)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-2000:]
    assert "0 broken" in run.stdout
