from kinfu_cli.cli import main

main()
