#!/usr/bin/env python3
"""The README as a front page that stays true (issue 23 part 6; CTest: readme.blocks).

- every code block announced by `<!-- examples/readme/FILE -->` is that file, verbatim (CTest
  builds and runs the files: readme.cpp, readme.cli, tests/python/test_examples.py);
- the test command of the quick start is the one .ci/run runs;
- every relative link and every repository path in backquotes that looks like a file exists
  (a repository that stands on its own: nothing points outside it);
- the README stays a front page: under 200 lines.
Standard library only."""
import pathlib
import re
import sys
import unittest

ROOT = pathlib.Path(__file__).resolve().parents[2]
README = ROOT / "README.md"


def readme():
    return README.read_text(encoding="utf-8")


class ReadmeTest(unittest.TestCase):
    def test_blocks_are_the_tested_files(self):
        blocks = re.findall(r"<!-- (examples/readme/[^ ]+) -->\n```[a-z]*\n(.*?)```", readme(), re.S)
        self.assertEqual(sorted(name for name, _ in blocks),
                         ["examples/readme/cart_pole.py", "examples/readme/cli.sh",
                          "examples/readme/pendulum.cpp"])
        for name, block in blocks:
            with self.subTest(name=name):
                self.assertEqual(block, (ROOT / name).read_text(encoding="utf-8"),
                                 f"README.md's block differs from {name}: edit both together")

    def test_ci_runs_the_readme_test_command(self):
        command = re.search(r"^bash scripts/setup\.sh .* && ctest --preset default$", readme(), re.M)
        self.assertIsNotNone(command, "README.md: the quick start's test command is missing")
        ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()
        self.assertIn(command.group(0), ci, ".ci/run must run exactly the README's test command")

    def test_links_and_paths_exist(self):
        text = readme()
        targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text)
        targets += [p for p in re.findall(r"`([A-Za-z_][\w./-]*/[\w.-]+\.(?:md|json|urdf|sh|py|cpp|png))`", text)
                    if not p.startswith(("build/", "output/"))]
        self.assertTrue(targets)
        missing = [t for t in targets if "://" not in t and not (ROOT / t).exists()]
        self.assertEqual(missing, [], "README.md names files that are not in the repository")
        self.assertNotIn("../", text, "README.md points outside the repository")

    def test_front_page_length(self):
        lines = len(readme().splitlines())
        self.assertLess(lines, 200, f"README.md has {lines} lines: move details to docs/")


if __name__ == "__main__":
    sys.exit(unittest.main())
