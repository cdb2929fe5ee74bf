"""`python -m ccgan.distill_range`: the command (`ccgan.distill_range.main`)."""

from ccgan.distill_range import main

main()
