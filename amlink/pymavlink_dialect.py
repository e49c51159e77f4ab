"""Stock pymavlink tools load the amstack dialect by name once amstack is installed.

``mavlogdump.py --dialect amstack``, MAVExplorer, ``mavproxy.py --dialect=amstack``,
``MAVLINK_DIALECT=amstack`` and ``mavutil.set_dialect("amstack")`` all import
``pymavlink.dialects.v20.amstack`` (``v10`` unless MAVLINK20 is set); when that fails,
pymavlink tries to generate it from an ``amstack.xml`` next to its own dialects or under
$MDEF, and raises FileNotFoundError.

Installing amstack (``pip install .`` or ``pip install -e .``) puts two files in
site-packages: this module, copied as ``_amstack_pymavlink.py``, and
``_amstack_pymavlink.pth``, whose one line imports it when the interpreter starts (see the
build backend, ``build_backend/amstack_build.py``).  :func:`install` appends a
:class:`DialectFinder` to ``sys.meta_path``: it answers those two module names, and no
others, with the module :mod:`amlink.dialect` generates from ``amlink/dialect/amstack.xml``
(generated on first use into amstack's cache, as the simulator and companions do).  Nothing
is written into pymavlink's folder, a read-only site-packages is fine, and uninstalling
amstack removes both files.  Start-up cost: importing this small module, no pymavlink.

Both names get the MAVLink 2 module: its parser reads MAVLink 1 frames too, and the amstack
messages exist only in MAVLink 2.
"""

from __future__ import annotations

import sys

DIALECT = "amstack"
MODULE_NAMES = (f"pymavlink.dialects.v20.{DIALECT}", f"pymavlink.dialects.v10.{DIALECT}")


class DialectFinder:
    """A ``sys.meta_path`` finder for :data:`MODULE_NAMES` only (after the regular finders)."""

    amstack_dialect_finder = True  # marks it across copies of this module

    def find_spec(self, fullname, path=None, target=None):
        if fullname not in MODULE_NAMES:
            return None
        import importlib.util

        try:
            from amlink import dialect

            module_path = dialect.generated_path()
            if not module_path.exists():
                dialect.generate(module_path)
        except Exception as exc:  # let pymavlink go on with its own search, and say why ours failed
            print(f"amstack: cannot provide the MAVLink dialect '{DIALECT}' to pymavlink: {exc}", file=sys.stderr)
            return None
        return importlib.util.spec_from_file_location(fullname, module_path)


def install() -> None:
    """Append the finder to ``sys.meta_path`` (once per interpreter)."""
    if not any(getattr(f, "amstack_dialect_finder", False) for f in sys.meta_path):
        sys.meta_path.append(DialectFinder())


if __name__ == "_amstack_pymavlink":  # the copy in site-packages, imported by _amstack_pymavlink.pth
    install()
