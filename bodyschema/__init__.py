"""bodyschema: a robot learns its body by motor babbling and perceives and moves it by active inference.

Subpackages (one direction of data flow): datagen → models → training → aif → evaluation.
"""

__version__ = "0.1.0"
