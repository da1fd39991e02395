from .app._cli import main

main()
