"""Where the tests find the repository's files, from one place: test modules sit at different depths."""
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
REPO = TESTS.parent
DATA = TESTS / "data"
EXAMPLES = REPO / "examples"
TOOLS = REPO / "tools"
CLIENTS = TESTS / "support" / "clients"
UML = TESTS / "support" / "uml"
