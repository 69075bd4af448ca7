"""``python -m benchmarks``: run the model benchmarks and rewrite benchmarks/RESULTS.md."""

import sys

from benchmarks.bench_model import main

sys.exit(main())
