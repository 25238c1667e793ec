from plumeswarm.cli.main import main

main()
