/* accelnav firmware entry point: the board runs the loop, the application does the work. */
#include "acn_board.h"

int main(void)
{
    board_init();
    app_init();
    while (board_poll()) {
    }
    return 0;
}
