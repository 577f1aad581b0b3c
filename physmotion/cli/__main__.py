"""``python -m physmotion.cli``: the console script."""

from physmotion.cli import main

if __name__ == "__main__":
    main()
