"""`python -m ccgan.distill`: the command (`ccgan.distill.main`)."""

from ccgan.distill import main

main()
